#include "tt_slcan.h"

static const char HEX[] = "0123456789ABCDEF";

void tt_slcan_init(tt_slcan *s)
{
    s->len = 0;
    s->overlong = false;
    s->open = true;
    s->timestamps = false;
    s->bitrate = 6;
    s->frames_in = s->bad_lines = s->dropped_closed = 0;
}

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    return -1;
}

/* `n` hex digits at `p` as a number, or -1. */
static int32_t hex_field(const char *p, unsigned n)
{
    int32_t v = 0;
    for (unsigned i = 0; i < n; i++) {
        int d = hex_digit(p[i]);
        if (d < 0) {
            return -1;
        }
        v = v * 16 + d;
    }
    return v;
}

static size_t put(char reply[TT_SLCAN_REPLY_MAX], const char *text)
{
    size_t n = 0;
    while (text[n] != '\0' && n < TT_SLCAN_REPLY_MAX) {
        reply[n] = text[n];
        n++;
    }
    return n;
}

/* A frame line: `idlen` hex digits of id, one of dlc, 2*dlc of data
 * (remote: none). Returns 0 with `frame` filled, -1 if malformed. */
static int parse_frame(const char *line, unsigned len, unsigned idlen, bool remote,
                       tt_can_frame *frame)
{
    if (len < 1u + idlen + 1u) {
        return -1;
    }
    int32_t id = hex_field(line + 1, idlen);
    int32_t dlc = hex_field(line + 1 + idlen, 1);
    if (id < 0 || dlc < 0 || dlc > 8 || (idlen == 3u && id > 0x7FF)) {
        return -1;
    }
    unsigned want = 1u + idlen + 1u + (remote ? 0u : 2u * (unsigned)dlc);
    if (len != want) {
        return -1;
    }
    frame->id = (uint16_t)(idlen == 3u ? id : 0);
    frame->dlc = (uint8_t)dlc;
    for (int32_t i = 0; !remote && i < dlc; i++) {
        int32_t b = hex_field(line + 1 + idlen + 1 + 2 * i, 2);
        if (b < 0) {
            return -1;
        }
        frame->data[i] = (uint8_t)b;
    }
    return 0;
}

/* A whole line (without its '\r'). Returns 1 for a frame for the driver,
 * 0 otherwise, -1 for a line to refuse. */
static int command(tt_slcan *s, tt_can_frame *frame, char reply[TT_SLCAN_REPLY_MAX],
                   size_t *reply_len)
{
    const char *l = s->line;
    unsigned n = s->len;
    tt_can_frame ignored;
    if (n == 0) {
        *reply_len = put(reply, "\r");
        return 0;
    }
    switch (l[0]) {
    case 't':
        if (parse_frame(l, n, 3, false, frame) != 0) {
            return -1;
        }
        if (!s->open) {
            s->dropped_closed++;
            return 0;
        }
        s->frames_in++;
        return 1;
    case 'T':
    case 'r':
    case 'R':
        return parse_frame(l, n, l[0] == 'r' ? 3u : 8u, l[0] != 'T', &ignored) != 0 ? -1 : 0;
    case 'O':
    case 'L':
    case 'C':
        if (n != 1) {
            return -1;
        }
        s->open = l[0] != 'C';
        break;
    case 'S':
        if (n != 2 || l[1] < '0' || l[1] > '8' || s->open) {
            return -1;
        }
        s->bitrate = (uint8_t)(l[1] - '0');
        break;
    case 'Z':
        if (n != 2 || (l[1] != '0' && l[1] != '1')) {
            return -1;
        }
        s->timestamps = l[1] == '1';
        break;
    case 'V':
        *reply_len = put(reply, n == 1 ? "V1013\r" : "\a");
        return n == 1 ? 0 : -1;
    case 'N':
        *reply_len = put(reply, n == 1 ? "NTT01\r" : "\a");
        return n == 1 ? 0 : -1;
    case 'F':
        *reply_len = put(reply, n == 1 ? "F00\r" : "\a");
        return n == 1 ? 0 : -1;
    default:
        return -1;
    }
    *reply_len = put(reply, "\r");
    return 0;
}

int tt_slcan_feed(tt_slcan *s, uint8_t byte, tt_can_frame *frame,
                  char reply[TT_SLCAN_REPLY_MAX], size_t *reply_len)
{
    *reply_len = 0;
    if (byte != '\r') {
        if (byte == '\n' && s->len == 0) {
            return 0; /* a "\r\n" line end: the \n is not a command */
        }
        if (s->len == TT_SLCAN_LINE_MAX) {
            s->overlong = true;
        } else {
            s->line[s->len++] = (char)byte;
        }
        return 0;
    }
    int r = s->overlong ? -1 : command(s, frame, reply, reply_len);
    s->len = 0;
    s->overlong = false;
    if (r < 0) {
        s->bad_lines++;
        *reply_len = put(reply, "\a");
        return 0;
    }
    return r;
}

size_t tt_slcan_format(const tt_slcan *s, const tt_can_frame *frame, uint32_t now_ms,
                       char out[TT_SLCAN_LINE_MAX])
{
    size_t n = 0;
    uint8_t dlc = frame->dlc > 8u ? 8u : frame->dlc;
    out[n++] = 't';
    out[n++] = HEX[(frame->id >> 8) & 0x7u];
    out[n++] = HEX[(frame->id >> 4) & 0xFu];
    out[n++] = HEX[frame->id & 0xFu];
    out[n++] = HEX[dlc];
    for (uint8_t i = 0; i < dlc; i++) {
        out[n++] = HEX[frame->data[i] >> 4];
        out[n++] = HEX[frame->data[i] & 0xFu];
    }
    if (s->timestamps) {
        uint32_t t = now_ms % TT_SLCAN_TIME_WRAP_MS;
        for (int shift = 12; shift >= 0; shift -= 4) {
            out[n++] = HEX[(t >> shift) & 0xFu];
        }
    }
    out[n++] = '\r';
    return n;
}
