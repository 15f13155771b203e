/* The STM32F405's clock tree, SysTick and USARTs at register level
 * (RM0090 sections 6, 8, 30; ARMv7-M B3.3 for SysTick). */
#include "board.h"

#include "../src/hal.h"
#include "regs.h"

static volatile uint32_t millis;
static uint32_t stamp_base; /* board_stamp's count when the tick changed (board_time_scale) */
static bool emulated;

#define RING 512u

typedef struct {
    volatile uint8_t buf[RING];
    volatile uint32_t head, tail; /* written by the interrupt / by the loop */
    volatile uint32_t overruns;
    volatile uint8_t tx[RING];
    volatile uint32_t tx_head, tx_tail; /* written by the loop / by the interrupt */
    bool held; /* board_uart_hold: the port's interrupt masked by the loop */
} uart;

static uart uarts[2];
static const uint32_t bases[2] = {USART1_BASE, USART2_BASE};
static const uint32_t irqns[2] = {USART1_IRQN, USART2_IRQN};

static bool wait_set(uint32_t mask)
{
    for (uint32_t i = 0; i < 1000000u; i++) {
        if (RCC_CR & mask) {
            return true;
        }
    }
    return false;
}

static bool clock_init(void)
{
    if (!(RCC_CR & RCC_CR_HSIRDY)) {
        emulated = true; /* no clock controller: see board.h */
        return true;
    }
    RCC_CR |= RCC_CR_HSEON;
    if (!wait_set(RCC_CR_HSERDY)) {
        return false;
    }
    /* 5 wait states at 168 MHz and 3.3 V (RM0090 table 10); caches, prefetch. */
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10);
    /* VCO = 8 MHz / M 8 * N 336 = 336 MHz; SYSCLK = VCO / P 2 = 168 MHz;
     * USB/SDIO = VCO / Q 7 = 48 MHz; source HSE. */
    RCC_PLLCFGR = 8u | (336u << 6) | (0u << 16) | (1u << 22) | (7u << 24);
    /* AHB /1, APB1 /4 (42 MHz), APB2 /2 (84 MHz). */
    RCC_CFGR = (5u << 10) | (4u << 13);
    RCC_CR |= RCC_CR_PLLON;
    if (!wait_set(RCC_CR_PLLRDY)) {
        return false;
    }
    RCC_CFGR = (RCC_CFGR & ~3u) | 2u; /* SYSCLK from the PLL */
    for (uint32_t i = 0; i < 1000000u; i++) {
        if (((RCC_CFGR >> 2) & 3u) == 2u) {
            return true;
        }
    }
    return false;
}

/* PA9/PA10 and PA2/PA3: alternate function 7 (USART1, USART2). */
static void pins_init(void)
{
    RCC_AHB1ENR |= RCC_AHB1ENR_GPIOA;
    uint32_t moder = GPIO_MODER(GPIOA_BASE);
    moder &= ~((3u << 18) | (3u << 20) | (3u << 4) | (3u << 6));
    moder |= (2u << 18) | (2u << 20) | (2u << 4) | (2u << 6);
    GPIO_MODER(GPIOA_BASE) = moder;
    GPIO_AFRH(GPIOA_BASE) = (GPIO_AFRH(GPIOA_BASE) & ~0xFF0u) | (7u << 4) | (7u << 8);
    GPIO_AFRL(GPIOA_BASE) = (GPIO_AFRL(GPIOA_BASE) & ~0xFF00u) | (7u << 8) | (7u << 12);
    GPIO_PUPDR(GPIOA_BASE) |= (1u << 20) | (1u << 6); /* RX lines pulled up: idle high */
}

static void uart_init(uint32_t base, uint32_t pclk_hz, uint32_t baud, uint32_t irqn)
{
    USART_CR1(base) = 0;
    /* Oversampling by 16: BRR = f_pclk / baud, rounded (RM0090 30.4.4). */
    USART_BRR(base) = (pclk_hz + baud / 2u) / baud;
    USART_CR2(base) = 0; /* 1 stop bit */
    USART_CR3(base) = 0;
    USART_CR1(base) = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    NVIC_ISER(irqn / 32u) = 1u << (irqn % 32u);
}

static void calibrate_isr_overhead(void);

bool board_init(void)
{
    bool ok = clock_init();
    RCC_APB2ENR |= RCC_APB2ENR_USART1;
    RCC_APB1ENR |= RCC_APB1ENR_USART2;
    pins_init();
    uart_init(bases[0], BOARD_APB2_HZ, BOARD_LINK_BAUD, USART1_IRQN);
    uart_init(bases[1], BOARD_APB1_HZ, BOARD_PLANT_BAUD, USART2_IRQN);
    SYST_RVR = BOARD_SYSCLK_HZ / 1000u - 1u;
    SYST_CVR = 0;
    SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
    __asm__ volatile("cpsie i" ::: "memory");
    calibrate_isr_overhead();
    return ok;
}

bool board_emulated(void)
{
    return emulated;
}

void board_fault(void)
{
    __asm__ volatile("cpsid i" ::: "memory");
    for (;;) {
        __asm__ volatile("wfi");
    }
}

void systick_handler(void)
{
    millis++;
}

volatile uint32_t board_loop_worst_cycles, board_loop_count, board_loop_worst_unit_cycles,
    board_loop_bursts, board_isr_worst_cycles;
/* SysTick counts spent in the UART interrupts since the start, and their
 * sum when the running iteration began; the same for the stand-in's work
 * (board_aside_*), which leaves the interrupts inside it to isr_cycles. */
static volatile uint32_t isr_cycles;
static uint32_t loop_isr_start;
static uint32_t aside_cycles, loop_aside_start, aside_isr_start;
volatile uint32_t board_aside_worst_cycles;

uint32_t board_stamp(void)
{
    uint32_t ms, cycles;
    do {
        ms = millis;
        cycles = SYST_RVR - SYST_CVR;
    } while (ms != millis);
    return stamp_base + ms * (SYST_RVR + 1u) + cycles;
}

bool board_time_scale(uint32_t scale_milli)
{
    if (scale_milli < BOARD_TIME_SCALE_MIN_MILLI || scale_milli > BOARD_TIME_SCALE_MAX_MILLI) {
        return false;
    }
    /* One tick every scale_milli / 1000 ms of the core's clock: at 168 MHz,
     * 168 counts a thousandth (24 bits hold 99 ms). The tick under way
     * ends now, counted whole (hal_micros never goes back), and the stamps
     * go on from where they were (stamp_base). */
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n\tcpsid i" : "=r"(primask)::"memory");
    SYST_CSR = 0;
    if (SCB_ICSR & SCB_ICSR_PENDSTSET) { /* a tick ended since the mask: its count */
        millis++;
        SCB_ICSR = SCB_ICSR_PENDSTCLR;
    }
    uint32_t stamp = board_stamp();
    SYST_RVR = (BOARD_SYSCLK_HZ / 1000000u) * scale_milli - 1u;
    SYST_CVR = 0;
    millis++;
    stamp_base = stamp - millis * (SYST_RVR + 1u);
    SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
    __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
    return true;
}

uint32_t board_loop_begin(void)
{
    /* Stamp first, then the interrupts' sum: an interrupt in between is
     * counted in the iteration (the measurement errs long, never short). */
    uint32_t start = board_stamp();
    loop_isr_start = isr_cycles;
    loop_aside_start = aside_cycles;
    return start;
}

uint32_t board_aside_begin(void)
{
    /* The interrupts' sum first, then the stamp (and the reverse at the
     * end): an interrupt between the two reads is taken out of the aside
     * without being in its span, so the aside errs short and the
     * iteration it is taken from errs long, never short. */
    aside_isr_start = isr_cycles;
    return board_stamp();
}

void board_aside_end(uint32_t start)
{
    uint32_t spent = board_stamp() - start;
    uint32_t in_isr = isr_cycles - aside_isr_start;
    spent = spent > in_isr ? spent - in_isr : 0u;
    aside_cycles += spent;
    if (spent > board_aside_worst_cycles) {
        board_aside_worst_cycles = spent;
    }
}

void board_loop_done(uint32_t start, uint32_t units)
{
    uint32_t in_isr = isr_cycles - loop_isr_start;
    uint32_t aside = aside_cycles - loop_aside_start;
    uint32_t cycles = board_stamp() - start;
    cycles = cycles > in_isr + aside ? cycles - in_isr - aside : 0u;
    if (units <= 1u) {
        if (cycles > board_loop_worst_cycles) {
            board_loop_worst_cycles = cycles;
        }
    } else {
        board_loop_bursts++;
        if (cycles / units > board_loop_worst_unit_cycles) {
            board_loop_worst_unit_cycles = cycles / units;
        }
    }
    board_loop_count++;
}

volatile uint32_t board_isr_overhead_cycles;

/* What an interrupt costs outside its handler's own stamps (uart_irq): the
 * handler's entry and bookkeeping, and on silicon the exception's entry
 * and return. A USART2 interrupt with nothing to do, pended by software and
 * timed around, less the span its stamps counted and a stamp's own cost
 * (timed with interrupts masked, so that none shortens the result); a try
 * counts only if the interrupt was taken in it, and the least of four is
 * kept (a SysTick inside a try only lengthens it). Under QEMU it is the
 * instructions alone: the exception costs none there. */
static void calibrate_isr_overhead(void)
{
    uint32_t least = UINT32_MAX;
    for (int i = 0; i < 4; i++) {
        __asm__ volatile("cpsid i" ::: "memory");
        uint32_t a = board_stamp();
        uint32_t stamp = board_stamp() - a;
        __asm__ volatile("cpsie i" ::: "memory");
        uint32_t counted = isr_cycles;
        uint32_t t0 = board_stamp();
        NVIC_ISPR(USART2_IRQN / 32u) = 1u << (USART2_IRQN % 32u);
        __asm__ volatile("dsb\n\tisb" ::: "memory"); /* taken here */
        uint32_t spent = board_stamp() - t0;
        uint32_t inside = isr_cycles - counted;
        if (inside > 0u && spent > stamp + inside && spent - stamp - inside < least) {
            least = spent - stamp - inside;
        }
    }
    board_isr_overhead_cycles = least; /* UINT32_MAX: no try counted (a reader says so) */
}

uint32_t hal_millis(void)
{
    return millis;
}

uint32_t hal_micros(void)
{
    /* The millisecond count and SysTick's down-counter, read again if the
     * tick's interrupt came in between. */
    uint32_t ms, cycles;
    do {
        ms = millis;
        cycles = SYST_RVR - SYST_CVR;
    } while (ms != millis);
    /* The counts of a tick (SYST_RVR + 1) are its 1000 us, whatever the
     * time scale (board_time_scale): the FPU's division (exact to well
     * under a microsecond for a tick's at most 24 bits of counts). */
    return ms * 1000u + (uint32_t)((float)cycles * 1000.0f / (float)(SYST_RVR + 1u));
}

/* A received byte into the ring. A full ring leaves the byte in the data
 * register and masks the USART's interrupt in the NVIC until the loop has
 * taken a byte (the NVIC mask works alike on silicon and in QEMU's model):
 * on silicon the next byte then overruns (counted when read); QEMU holds
 * its input while the register is full, so nothing is lost there. */
static void uart_rx(int port, uint32_t sr)
{
    uart *u = &uarts[port];
    uint32_t next = (u->head + 1u) % RING;
    if (next == u->tail) {
        NVIC_ICER(irqns[port] / 32u) = 1u << (irqns[port] % 32u);
        return;
    }
    uint8_t byte = (uint8_t)USART_DR(bases[port]); /* clears RXNE and ORE */
    if (sr & USART_SR_ORE) {
        u->overruns++;
    }
    u->buf[u->head] = byte;
    u->head = next;
}

/* Queued bytes into the data register while it is empty; the interrupt
 * off when nothing is left. Called by the transmit interrupt and, with
 * interrupts masked, after queuing: on silicon the register takes a byte
 * or two and the interrupt sends the rest as the line frees it; QEMU's
 * model has the register empty at once and raises no interrupt for it, so
 * there the call after queuing sends everything. */
static void uart_tx(int port)
{
    uart *u = &uarts[port];
    uint32_t base = bases[port];
    while (USART_SR(base) & USART_SR_TXE) {
        if (u->tx_tail == u->tx_head) {
            USART_CR1(base) &= ~USART_CR1_TXEIE;
            return;
        }
        USART_DR(base) = u->tx[u->tx_tail];
        u->tx_tail = (u->tx_tail + 1u) % RING;
    }
}

static void uart_irq(int port)
{
    uint32_t entry = SYST_CVR; /* SysTick counts down, reloading every millisecond */
    uint32_t base = bases[port];
    uint32_t sr = USART_SR(base);
    if (sr & (USART_SR_RXNE | USART_SR_ORE)) {
        uart_rx(port, sr);
    }
    if ((sr & USART_SR_TXE) && (USART_CR1(base) & USART_CR1_TXEIE)) {
        uart_tx(port);
    }
    uint32_t exit = SYST_CVR;
    uint32_t spent = entry >= exit ? entry - exit : entry + SYST_RVR + 1u - exit;
    isr_cycles += spent;
    if (spent > board_isr_worst_cycles) {
        board_isr_worst_cycles = spent;
    }
}

void usart1_handler(void)
{
    uart_irq(0);
}

void usart2_handler(void)
{
    uart_irq(1);
}

int board_uart_getc(int port)
{
    uart *u = &uarts[port];
    if (u->tail == u->head) {
        return -1;
    }
    uint8_t byte = u->buf[u->tail];
    u->tail = (u->tail + 1u) % RING;
    if (!u->held) {
        NVIC_ISER(irqns[port] / 32u) = 1u << (irqns[port] % 32u); /* room again: see uart_irq */
    }
    return byte;
}

void board_uart_hold(int port, bool hold)
{
    uart *u = &uarts[port];
    u->held = hold;
    if (hold) {
        NVIC_ICER(irqns[port] / 32u) = 1u << (irqns[port] % 32u);
        __asm__ volatile("dsb\n\tisb" ::: "memory"); /* masked from the next instruction */
    } else {
        /* A full ring masks it again at the first interrupt (uart_rx). */
        NVIC_ISER(irqns[port] / 32u) = 1u << (irqns[port] % 32u);
    }
}

uint32_t board_uart_overruns(int port)
{
    return uarts[port].overruns;
}

static uint32_t tx_room(const uart *u)
{
    return (u->tx_tail + RING - u->tx_head - 1u) % RING;
}

bool board_uart_try_write(int port, const uint8_t *data, size_t len)
{
    uart *u = &uarts[port];
    if (len > tx_room(u)) {
        return false;
    }
    uint32_t head = u->tx_head;
    for (size_t i = 0; i < len; i++) {
        u->tx[head] = data[i];
        head = (head + 1u) % RING;
    }
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n\tcpsid i" : "=r"(primask)::"memory");
    u->tx_head = head;
    USART_CR1(bases[port]) |= USART_CR1_TXEIE; /* the interrupt sends the rest */
    uart_tx(port);
    __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
    return true;
}

void board_uart_write(int port, const uint8_t *data, size_t len)
{
    while (len) {
        size_t room = tx_room(&uarts[port]);
        size_t n = len < room ? len : room;
        if (n == 0) {
            if (uarts[port].held) {
                uart_tx(port); /* its interrupt is masked: the register polled */
            } else {
                board_wait(); /* the transmit interrupt makes room */
            }
            continue;
        }
        board_uart_try_write(port, data, n);
        data += n;
        len -= n;
    }
}

void board_wait(void)
{
    __asm__ volatile("wfi");
}
