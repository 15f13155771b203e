/* The codec image: the firmware's codecs (host/tt_codec.c, the same code
 * tt_host runs) on the microcontroller, stdin and stdout on USART1, so
 * that the golden vectors are checked on the core's own compiler output,
 * byte order and float unit. A session on the link:
 *
 *   PC -> board:  a mode line ("selftest", "serial-encode" or "can-codec"),
 *                 the mode's input lines, then 0x04 (end of input)
 *   board -> PC:  the mode's output, then 0x1E "exit <status>\n"
 *
 * then it waits for the next mode line. At reset it sends 0x1E "ready\n"
 * (bytes sent before the UART is set up are lost). Not flashed on a lab's board: a
 * test image. */
#include <stdio.h>
#include <string.h>

#include "../host/tt_codec.h"
#include "board.h"

#define END_OF_INPUT 0x04
#define RECORD_SEPARATOR 0x1E

static int link_putc(char c, FILE *f)
{
    (void)f;
    const uint8_t byte = (uint8_t)c;
    board_uart_write(BOARD_LINK, &byte, 1);
    return (unsigned char)c;
}

static int link_getc(FILE *f)
{
    (void)f;
    int c;
    while ((c = board_uart_getc(BOARD_LINK)) < 0) {
        board_wait();
    }
    return c == END_OF_INPUT ? _FDEV_EOF : c;
}

static FILE link = FDEV_SETUP_STREAM(link_putc, link_getc, NULL, _FDEV_SETUP_RW);
FILE *const stdin = &link;
FILE *const stdout = &link;
FILE *const stderr = &link;

static int run(const char *mode)
{
    if (strcmp(mode, "selftest") == 0) {
        return tt_codec_selftest();
    }
    if (strcmp(mode, "serial-encode") == 0) {
        return tt_codec_serial_encode();
    }
    if (strcmp(mode, "can-codec") == 0) {
        return tt_codec_can();
    }
    printf("codec: unknown mode '%s' (selftest, serial-encode, can-codec)\n", mode);
    return 2;
}

int main(void)
{
    if (!board_init()) {
        board_fault();
    }
    char line[64];
    printf("%cready\n", RECORD_SEPARATOR); /* the PC may send from now on */
    for (;;) {
        clearerr(stdin);
        if (!fgets(line, sizeof line, stdin)) {
            continue; /* an end of input with no mode: ignored */
        }
        line[strcspn(line, "\r\n")] = '\0';
        if (line[0] == '\0') {
            continue;
        }
        int status = run(line);
        while (!feof(stdin) && getc(stdin) != EOF) {
            /* a mode that stopped early: its unread input is dropped */
        }
        clearerr(stdin);
        printf("%cexit %d\n", RECORD_SEPARATOR, status);
    }
}
