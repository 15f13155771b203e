/* The STM32F405 port's own functions (not part of the portable HAL): the
 * clock, the UARTs and the interrupt handlers the vector table names.
 *
 * Pins (the Olimex STM32-H405's headers; any STM32F405RG board has them):
 *   USART1 PA9 TX, PA10 RX, 921600 baud: the link to the PC (the sensor
 *          board's frames; the Peltier driver's SLCAN; the codec image's text)
 *   USART2 PA2 TX, PA3 RX, 460800 baud: the plant link (processor in the
 *          loop: the analog readings in, the H-bridge command out) */
#ifndef TT_STM32F4_BOARD_H
#define TT_STM32F4_BOARD_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* The core clock the port runs at: 168 MHz from the 8 MHz crystal through
 * the PLL (the part's maximum); APB1 42 MHz, APB2 84 MHz. */
#define BOARD_SYSCLK_HZ 168000000u
#define BOARD_HSE_HZ 8000000u
#define BOARD_APB1_HZ (BOARD_SYSCLK_HZ / 4u)
#define BOARD_APB2_HZ (BOARD_SYSCLK_HZ / 2u)
#define BOARD_LINK_BAUD 921600u
#define BOARD_PLANT_BAUD 460800u

/* Clocks, SysTick (1 kHz), both UARTs. Returns false if the crystal or the
 * PLL did not start (the caller parks in board_fault). On an emulator
 * without a clock controller (QEMU's STM32F405 reads RCC as 0: HSI never
 * "ready", impossible on silicon) the core already runs at 168 MHz and the
 * clock tree is left alone; board_emulated() then says true. */
bool board_init(void);
bool board_emulated(void);

/* Never returns: interrupts off, the core parked (a stray interrupt, a
 * clock that did not start). */
void board_fault(void) __attribute__((noreturn));

/* Core cycles since the start, from SysTick (wraps every 25.6 s; take
 * differences). */
uint32_t board_stamp(void);

/* Processor in the loop, a rig slower than real time: SysTick's tick (the
 * HAL's millisecond: hal_millis, hal_micros, every timeout and the
 * watchdog) every scale_milli / 1000 ms of the core's clock, so that the
 * firmware's time runs as the simulated plant's and the services' do
 * (telethermal's time_scale; plant.c's "k" line). 1000 (the default) is
 * real time; 1000-99000, else refused (false). On silicon nothing sends it. */
#define BOARD_TIME_SCALE_MIN_MILLI 1000u
#define BOARD_TIME_SCALE_MAX_MILLI 99000u
bool board_time_scale(uint32_t scale_milli);

/* The loop-time measurement, in core cycles (a debugger, or QEMU's monitor,
 * reads the figures). An iteration begins with board_loop_begin and ends
 * with board_loop_done, having handled `units` pieces of work (command
 * frames taken, samples framed). The time spent in the UART interrupts
 * meanwhile is left out of the iteration and kept apart: on silicon a byte
 * comes at most every 10.9 us (921600 baud), so an iteration sees a few;
 * QEMU models no baud rate and hands over a burst the host wrote at once,
 * so there an iteration can hold any number of them.
 *   board_loop_worst_cycles   the worst iteration that handled at most one
 *                             unit (interrupts left out)
 *   board_loop_worst_unit_cycles, board_loop_bursts
 *                             over iterations that handled more than one
 *                             (only a burst delivered at once does that:
 *                             on silicon the loop wakes at every byte), the
 *                             worst cycles per unit, and their number
 *   board_isr_worst_cycles    the worst single UART interrupt
 *   board_loop_count          iterations */
uint32_t board_loop_begin(void);
void board_loop_done(uint32_t start, uint32_t units);
extern volatile uint32_t board_loop_worst_cycles, board_loop_count, board_loop_worst_unit_cycles,
    board_loop_bursts, board_isr_worst_cycles;
/* What an interrupt costs outside the span board_isr_worst_cycles counts
 * (the handler's entry and bookkeeping; on silicon also the exception's
 * entry and return), measured once by board_init; UINT32_MAX if that
 * failed. */
extern volatile uint32_t board_isr_overhead_cycles;

/* The processor-in-the-loop stand-in's own work (plant.c: the text lines
 * that stand for the ADC conversions and for the H-bridge's and the water
 * loop's outputs), wherever it runs, is left out of the iteration as the
 * interrupts are: its span, between
 * board_aside_begin and board_aside_end, less the interrupts in it.
 *   board_aside_worst_cycles  the worst such span (for the record) */
uint32_t board_aside_begin(void);
void board_aside_end(uint32_t start);
extern volatile uint32_t board_aside_worst_cycles;

/* The UARTs: 0 = USART1 (the link to the PC), 1 = USART2 (the plant). */
enum { BOARD_LINK = 0, BOARD_PLANT = 1 };
/* Queue `len` bytes for the transmit interrupt (a 512-byte ring): false,
 * and nothing queued, if they do not fit whole. */
bool board_uart_try_write(int port, const uint8_t *data, size_t len);
/* The same, waiting for room (the loop sleeps while the interrupt sends). */
void board_uart_write(int port, const uint8_t *data, size_t len);
/* The next received byte, or -1 if none is waiting. Received bytes wait in
 * a 512-byte ring filled by the receive interrupt; when it is full the
 * interrupt waits for room, and `board_uart_overruns` counts the bytes the
 * UART lost meanwhile (its overrun flag). */
int board_uart_getc(int port);
/* Mask (true) or unmask the port's interrupt (receive and transmit: one
 * line in the NVIC) for a while: received bytes wait in the UART meanwhile
 * (on silicon the second one overruns) and board_uart_write sends by
 * polling the data register. For the processor-in-the-loop stand-in's port
 * under QEMU only (plant_hold). */
void board_uart_hold(int port, bool hold);
uint32_t board_uart_overruns(int port);

/* Sleep until the next interrupt (SysTick each millisecond, or a byte). */
void board_wait(void);

void systick_handler(void);
void usart1_handler(void);
void usart2_handler(void);

#endif
