/* hal_can_send / hal_can_receive as SLCAN on USART1 (src/tt_slcan.h): the
 * board is both the CAN node and its own USB-CAN adapter, so the PC's
 * python-can `slcan` interface is its bus. The build's default: under QEMU,
 * which emulates no CAN controller, and on a bench without transceivers.
 * CAN=bxcan builds can_bxcan.c instead. */
#include "can_slcan.h"

#include "../src/hal.h"
#include "board.h"

static tt_slcan link;
static bool started;

const tt_slcan *can_link(void)
{
    return &link;
}

static void start(void)
{
    if (!started) {
        tt_slcan_init(&link);
        started = true;
    }
}

int hal_can_send(uint16_t id, const uint8_t *data, uint8_t dlc)
{
    start();
    if (!link.open || dlc > 8u) {
        return -1; /* the adapter is off the bus: nobody to send to */
    }
    tt_can_frame frame = {id, dlc, {0}};
    for (uint8_t i = 0; i < dlc; i++) {
        frame.data[i] = data[i];
    }
    char line[TT_SLCAN_LINE_MAX];
    size_t n = tt_slcan_format(&link, &frame, hal_millis(), line);
    board_uart_write(BOARD_LINK, (const uint8_t *)line, n);
    return 0;
}

int hal_can_receive(uint16_t *id, uint8_t *data, uint8_t *dlc)
{
    start();
    int c;
    while ((c = board_uart_getc(BOARD_LINK)) >= 0) {
        tt_can_frame frame;
        char reply[TT_SLCAN_REPLY_MAX];
        size_t reply_len;
        int got = tt_slcan_feed(&link, (uint8_t)c, &frame, reply, &reply_len);
        if (reply_len) {
            board_uart_write(BOARD_LINK, (const uint8_t *)reply, reply_len);
        }
        if (got) {
            *id = frame.id;
            *dlc = frame.dlc;
            for (uint8_t i = 0; i < frame.dlc; i++) {
                data[i] = frame.data[i];
            }
            return 1;
        }
    }
    return 0;
}
