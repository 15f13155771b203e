/* The Peltier driver on the STM32F405 (TT_ACTIVE_PAD: the slave's active
 * pad, node 2): the portable driver (src/tt_peltier.c) polled at every
 * interrupt (SysTick each millisecond, a received byte), the core asleep
 * in between. Each iteration's length in core cycles is measured, with
 * the command frames it handled (board_loop_done). */
#include "../src/hal.h"
#include "../src/tt_peltier.h"
#include "board.h"
#include "plant.h"

#ifndef TT_ACTIVE_PAD
#define TT_ACTIVE_PAD 0
#endif

static tt_peltier_driver drv;

int main(void)
{
    if (!board_init()) {
        board_fault();
    }
    plant_start();
    tt_peltier_config cfg;
    if (TT_ACTIVE_PAD) {
        tt_pad_default_config(&cfg);
    } else {
        tt_peltier_default_config(&cfg);
    }
    tt_peltier_init(&drv, &cfg);
    for (;;) {
        plant_poll(); /* the analog side: outside the measurement (plant.h) */
        plant_hold(true);
        uint32_t start = board_loop_begin();
        uint32_t frames = drv.commands + drv.bad_commands;
        tt_peltier_poll(&drv);
        board_loop_done(start, drv.commands + drv.bad_commands - frames);
        plant_hold(false);
        board_wait();
    }
}
