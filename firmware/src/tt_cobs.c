#include "tt_cobs.h"

size_t tt_cobs_encode(const uint8_t *in, size_t len, uint8_t *out)
{
    size_t code_at = 0; /* where the current block's code byte goes */
    size_t o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < len; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            code++;
            if (code == 0xFF) {          /* a full block of 254 non-zero bytes */
                out[code_at] = code;
                code_at = o++;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    return o;
}

size_t tt_cobs_decode(const uint8_t *in, size_t len, uint8_t *out)
{
    size_t i = 0, o = 0;
    while (i < len) {
        uint8_t code = in[i++];
        if (code == 0) {
            return (size_t)-1;
        }
        for (uint8_t k = 1; k < code; k++) {
            if (i >= len || in[i] == 0) {
                return (size_t)-1;
            }
            out[o++] = in[i++];
        }
        if (code != 0xFF && i < len) {
            out[o++] = 0;
        }
    }
    return o;
}
