/* SLCAN (the Lawicel serial CAN protocol of USB-CAN adapters: CANable,
 * USBtin, CANUSB), the adapter's side: lets a board with no CAN controller
 * the PC can reach (an emulated core, a bench without transceivers) be a
 * node on python-can's `slcan` bus. The CAN protocol on top (CAN.md) is
 * unchanged: the frames are the same bytes.
 *
 * Lines end in '\r'. From the PC:
 *   O, L          open the channel (L: listen only; both answered "\r");
 *                 it is open from the start: the board is a node on the
 *                 bus from its reset, and a restarted board is heard at
 *                 once by a PC that opened the channel before
 *   C             close it ("\r"): the board's frames are dropped (counted
 *                 by the driver as failed sends) until O; S0..S8 the bit
 *                 rate, accepted when closed
 *   V, N, F       version "V1013\r", serial "NTT01\r", status flags "F00\r"
 *   Z0, Z1        timestamps off/on: 4 hex digits of the board's
 *                 milliseconds modulo 60000 after each frame it sends
 *   tIIILDD..     a classic frame, 11-bit id, dlc 0..8: handed to the
 *                 driver if the channel is open; not answered (Lawicel's
 *                 adapters answer "z\r": python-can's slcan reads that as
 *                 an empty read, which ends a non-blocking poll after one
 *                 line, so a board answering every command would be read
 *                 one frame per poll)
 *   TIIIIIIIIL.., rIIIL, RIIIIIIIIL  extended and remote frames: dropped,
 *                 not answered (the drivers use 11-bit data frames)
 *   "" (a bare \r) answered "\r"
 * Anything else (an unknown command, a bad hex digit, a dlc above 8, data
 * of the wrong length, a line longer than any command) is answered "\a"
 * (BEL) and counted in `bad_lines`; the parser starts afresh at the next
 * '\r'. To the PC, the board's own frames: "tIIILDD..[TTTT]\r". */
#ifndef TT_SLCAN_H
#define TT_SLCAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* The longest line either way: 't' id(3) dlc(1) data(16) time(4) '\r'. */
#define TT_SLCAN_LINE_MAX 26u
/* The longest answer to a command ("V1013\r"). */
#define TT_SLCAN_REPLY_MAX 8u
#define TT_SLCAN_TIME_WRAP_MS 60000u

typedef struct {
    uint16_t id;
    uint8_t dlc;
    uint8_t data[8];
} tt_can_frame;

typedef struct {
    char line[TT_SLCAN_LINE_MAX];
    uint8_t len;
    bool overlong;   /* the line outgrew the buffer: refused at its '\r' */
    bool open;       /* from the start, and after O or L; not after C */
    bool timestamps; /* Z1 */
    uint8_t bitrate; /* S0..S8, as sent (6, 500 kbit/s, until told) */
    uint32_t frames_in, bad_lines, dropped_closed;
} tt_slcan;

void tt_slcan_init(tt_slcan *s);

/* One received byte. Returns 1 when it completed a classic data frame for
 * the driver (`frame` filled), else 0. Whatever the line asks to be
 * answered is put in `reply` (its length in `*reply_len`, 0 for none). */
int tt_slcan_feed(tt_slcan *s, uint8_t byte, tt_can_frame *frame,
                  char reply[TT_SLCAN_REPLY_MAX], size_t *reply_len);

/* The board's frame as a line (with the timestamp if Z1); returns its
 * length. */
size_t tt_slcan_format(const tt_slcan *s, const tt_can_frame *frame, uint32_t now_ms,
                       char out[TT_SLCAN_LINE_MAX]);

#endif
