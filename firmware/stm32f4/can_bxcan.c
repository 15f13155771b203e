/* hal_can_send / hal_can_receive on the STM32F405's own CAN controller
 * (bxCAN, CAN1; RM0090 section 32), for a board with a transceiver (e.g.
 * an SN65HVD230 on PB8 RX / PB9 TX). Built with `make TARGET=stm32f405
 * CAN=bxcan`.
 *
 * UNTESTED: QEMU emulates no CAN controller and no board was at hand; it
 * compiles with the port's warnings as errors and follows RM0090's
 * initialisation sequence, nothing more is claimed. Bring it up with the
 * README's checklist (a scope on CANH/CANL, a USB-CAN adapter listening).
 *
 * 500 kbit/s from APB1's 42 MHz: prescaler 6 (7 MHz, 14 time quanta per
 * bit), BS1 11, BS2 2, SJW 1: sample point at 12/14 = 85.7 %. Automatic
 * bus-off recovery; every standard frame accepted into FIFO 0 (the driver
 * ignores identifiers that are not its own). */
#include "../src/hal.h"
#include "board.h"
#include "regs.h"

#define MCR_INRQ (1u << 0)
#define MCR_SLEEP (1u << 1)
#define MCR_TXFP (1u << 2)
#define MCR_ABOM (1u << 6)
#define MSR_INAK (1u << 0)
#define TSR_TME(n) (1u << (26u + (n)))
#define TIR_TXRQ (1u << 0)
#define RIR_IDE (1u << 2)
#define RIR_RTR (1u << 1)
#define RF0R_RFOM0 (1u << 5)
#define FMR_FINIT (1u << 0)

static bool ready;

static bool wait_inak(bool set)
{
    for (uint32_t i = 0; i < 1000000u; i++) {
        if (((CAN_MSR & MSR_INAK) != 0u) == set) {
            return true;
        }
    }
    return false;
}

static void can_init(void)
{
    ready = true;
    RCC_AHB1ENR |= RCC_AHB1ENR_GPIOB;
    RCC_APB1ENR |= RCC_APB1ENR_CAN1;
    /* PB8, PB9: alternate function 9 (CAN1). */
    GPIO_MODER(GPIOB_BASE) = (GPIO_MODER(GPIOB_BASE) & ~(0xFu << 16)) | (0xAu << 16);
    GPIO_AFRH(GPIOB_BASE) = (GPIO_AFRH(GPIOB_BASE) & ~0xFFu) | 0x99u;
    CAN_MCR = (CAN_MCR & ~MCR_SLEEP) | MCR_INRQ;
    if (!wait_inak(true)) {
        board_fault(); /* the controller did not enter initialisation */
    }
    CAN_BTR = (6u - 1u) | ((11u - 1u) << 16) | ((2u - 1u) << 20) | (0u << 24);
    CAN_MCR = MCR_ABOM | MCR_TXFP | MCR_INRQ;
    /* Filter 0: 32-bit mask mode, mask 0 (every frame), FIFO 0. */
    CAN_FMR |= FMR_FINIT;
    CAN_FA1R &= ~1u;
    CAN_FS1R |= 1u;
    CAN_FM1R &= ~1u;
    CAN_FFA1R &= ~1u;
    CAN_FR1(0) = 0;
    CAN_FR2(0) = 0;
    CAN_FA1R |= 1u;
    CAN_FMR &= ~FMR_FINIT;
    CAN_MCR &= ~MCR_INRQ;
    if (!wait_inak(false)) {
        board_fault(); /* no 11 recessive bits seen: no bus, or no transceiver */
    }
}

int hal_can_send(uint16_t id, const uint8_t *data, uint8_t dlc)
{
    if (!ready) {
        can_init();
    }
    for (uint32_t box = 0; box < 3u; box++) {
        if (CAN_TSR & TSR_TME(box)) {
            uint32_t lo = 0, hi = 0;
            for (uint8_t i = 0; i < dlc && i < 8u; i++) {
                if (i < 4u) {
                    lo |= (uint32_t)data[i] << (8u * i);
                } else {
                    hi |= (uint32_t)data[i] << (8u * (i - 4u));
                }
            }
            CAN_TIR(box) = (uint32_t)(id & 0x7FFu) << 21;
            CAN_TDTR(box) = dlc & 0xFu;
            CAN_TDLR(box) = lo;
            CAN_TDHR(box) = hi;
            CAN_TIR(box) |= TIR_TXRQ;
            return 0;
        }
    }
    return -1; /* three frames already waiting: dropped, counted by the driver */
}

int hal_can_receive(uint16_t *id, uint8_t *data, uint8_t *dlc)
{
    if (!ready) {
        can_init();
    }
    while (CAN_RF0R & 3u) {
        uint32_t rir = CAN_RI0R, rdtr = CAN_RDT0R, lo = CAN_RDL0R, hi = CAN_RDH0R;
        CAN_RF0R |= RF0R_RFOM0; /* release the FIFO slot */
        if (rir & (RIR_IDE | RIR_RTR)) {
            continue; /* extended or remote: not ours */
        }
        *id = (uint16_t)((rir >> 21) & 0x7FFu);
        *dlc = (uint8_t)(rdtr & 0xFu) > 8u ? 8u : (uint8_t)(rdtr & 0xFu);
        for (uint8_t i = 0; i < *dlc; i++) {
            data[i] = (uint8_t)((i < 4u ? lo >> (8u * i) : hi >> (8u * (i - 4u))) & 0xFFu);
        }
        return 1;
    }
    return 0;
}
