/* The SLCAN link's state, for a diagnostics read-out (main_peltier.c). */
#ifndef TT_STM32F4_CAN_SLCAN_H
#define TT_STM32F4_CAN_SLCAN_H

#include "../src/tt_slcan.h"

/* The link's parser (counters: frames_in, bad_lines, dropped_closed). */
const tt_slcan *can_link(void);

#endif
