/* Reset and the vector table of the STM32F405 (RM0090 12.2, table 61: the
 * 82 maskable interrupts after the core's 16 entries). At reset: .data and
 * the thread-local block copied from flash, .bss zeroed, the FPU enabled
 * (the sensor board's frames carry floats), then main(). Every interrupt
 * this port does not use goes to default_handler, which parks the core: a
 * stray interrupt is a bug, and a parked Peltier driver has already set its
 * H-bridge off or is stopped by the board's hardware (see README). */
#include <stdint.h>

#include "board.h"
#include "regs.h"

extern uint32_t _stack_top, _data_load, _data_start, _data_end, _bss_start, _bss_end;
extern uint32_t _tdata_load, _tls_start, _tdata_end, _tls_end;

int main(void);
void reset_handler(void);
void default_handler(void);
void _set_tls(void *tls); /* picolibc: where errno lives */

static void copy_words(uint32_t *dst, const uint32_t *src, const uint32_t *end)
{
    while (dst < end) {
        *dst++ = *src++;
    }
}

static void zero_words(uint32_t *dst, const uint32_t *end)
{
    while (dst < end) {
        *dst++ = 0;
    }
}

void reset_handler(void)
{
    copy_words(&_data_start, &_data_load, &_data_end);
    zero_words(&_bss_start, &_bss_end);
    copy_words(&_tls_start, &_tdata_load, &_tdata_end);
    zero_words(&_tdata_end, &_tls_end);
    _set_tls(&_tls_start);
    SCB_CPACR |= 0xFu << 20; /* CP10, CP11: the FPU, full access */
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    main();
    for (;;) {
    }
}

void default_handler(void)
{
    board_fault();
}

#define VECTORS (16u + 82u)

typedef void (*vector)(void);

__attribute__((section(".isr_vector"), used)) static const vector vector_table[VECTORS] = {
    [0] = (vector)(uintptr_t)&_stack_top,
    [1] = reset_handler,
    [2 ... 14] = default_handler, /* NMI, the faults, SVC, PendSV */
    [15] = systick_handler,
    [16 ... 16 + USART1_IRQN - 1] = default_handler,
    [16 + USART1_IRQN] = usart1_handler,
    [16 + USART2_IRQN] = usart2_handler,
    [16 + USART2_IRQN + 1 ... VECTORS - 1] = default_handler,
};
