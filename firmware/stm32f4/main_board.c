/* The sensor board on the STM32F405: the portable application
 * (src/tt_board.c), its frames on USART1, its samples from plant.c. The
 * frame version is TT_BOARD_VERSION (1, the display's board) unless built
 * with -DTT_BOARD_FRAME_VERSION=2 (the slave's). Each iteration's length
 * in core cycles is measured (board_loop_done). */
#include "../src/tt_board.h"
#include "board.h"
#include "plant.h"

#ifndef TT_BOARD_FRAME_VERSION
#define TT_BOARD_FRAME_VERSION TT_BOARD_VERSION
#endif

static tt_board_app app;

int main(void)
{
    if (!board_init()) {
        board_fault();
    }
    plant_start();
    tt_board_app_start(&app, TT_BOARD_FRAME_VERSION, 25.0f);
    for (;;) {
        plant_poll(); /* the analog side: outside the measurement (plant.h) */
        plant_hold(true);
        uint32_t start = board_loop_begin();
        int sent = tt_board_app_poll(&app);
        board_loop_done(start, sent > 0 ? (uint32_t)sent : 0u);
        plant_hold(false);
        if (sent == 0) {
            board_wait();
        }
    }
}
