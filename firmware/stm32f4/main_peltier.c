/* The Peltier driver on the STM32F405 (TT_ACTIVE_PAD: the slave's active
 * pad, node 2): the portable driver (src/tt_peltier.c) polled at every
 * interrupt (SysTick each millisecond, a received byte), the core asleep
 * in between. Each iteration's length in core cycles is kept (the worst in
 * `loop_cycles_max`, for a debugger and the QEMU measurement). */
#include "../src/hal.h"
#include "../src/tt_peltier.h"
#include "board.h"

#ifndef TT_ACTIVE_PAD
#define TT_ACTIVE_PAD 0
#endif

static tt_peltier_driver drv;
volatile uint32_t loop_cycles_max; /* the worst iteration so far, core cycles */
volatile uint32_t loop_iterations;

static uint32_t cycles_since(uint32_t ms0, uint32_t c0)
{
    uint32_t ms1, c1;
    do {
        ms1 = hal_millis();
        c1 = board_cycles();
    } while (ms1 != hal_millis());
    return (ms1 - ms0) * (BOARD_SYSCLK_HZ / 1000u) + c1 - c0;
}

int main(void)
{
    if (!board_init()) {
        board_fault();
    }
    tt_peltier_config cfg;
    if (TT_ACTIVE_PAD) {
        tt_pad_default_config(&cfg);
    } else {
        tt_peltier_default_config(&cfg);
    }
    tt_peltier_init(&drv, &cfg);
    for (;;) {
        uint32_t ms0, c0;
        do {
            ms0 = hal_millis();
            c0 = board_cycles();
        } while (ms0 != hal_millis());
        tt_peltier_poll(&drv);
        uint32_t cycles = cycles_since(ms0, c0);
        if (cycles > loop_cycles_max) {
            loop_cycles_max = cycles;
        }
        loop_iterations++;
        board_wait();
    }
}
