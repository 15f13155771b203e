# The STM32F405 port (included by ../Makefile with TARGET=stm32f405).
# Cortex-M4F at 168 MHz, hard-float ABI; picolibc for memcpy/memset and,
# in the codec image only, stdio.
CROSS ?= arm-none-eabi-
CAN ?= slcan
ARCH := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16
ARM_CFLAGS := -std=gnu11 -Wall -Wextra -Werror -Os -g -ffunction-sections -fdata-sections \
	$(ARCH) --specs=picolibc.specs
ARM_LDFLAGS := -nostartfiles -T stm32f4/stm32f405.ld \
	-Wl,--gc-sections -Wl,--no-warn-rwx-segments
OUT := $(BUILD)/stm32f405
PORT := stm32f4/startup.c stm32f4/board.c
PORT_H := $(wildcard stm32f4/*.h)
CAN_SRC := $(if $(filter bxcan,$(CAN)),stm32f4/can_bxcan.c,stm32f4/can_slcan.c)
IMAGES := tt_board tt_board2 tt_peltier tt_pad tt_codec

all: $(foreach i,$(IMAGES),$(OUT)/$(i).elf $(OUT)/$(i).bin)
	$(CROSS)size $(foreach i,$(IMAGES),$(OUT)/$(i).elf)

$(OUT)/tt_board.elf: $(SRC) $(PORT) stm32f4/main_board.c stm32f4/plant.c $(HEADERS) $(PORT_H)
	mkdir -p $(OUT)
	$(CROSS)gcc $(ARM_CFLAGS) $(ARM_LDFLAGS) -o $@ $(SRC) $(PORT) stm32f4/main_board.c \
		stm32f4/plant.c

# The slave's board: frame version 2 (the IR thermometer, the pad's drive).
$(OUT)/tt_board2.elf: $(SRC) $(PORT) stm32f4/main_board.c stm32f4/plant.c $(HEADERS) $(PORT_H)
	mkdir -p $(OUT)
	$(CROSS)gcc $(ARM_CFLAGS) -DTT_BOARD_FRAME_VERSION=2 $(ARM_LDFLAGS) -o $@ $(SRC) $(PORT) \
		stm32f4/main_board.c stm32f4/plant.c

$(OUT)/tt_peltier.elf: $(SRC) $(PORT) stm32f4/main_peltier.c stm32f4/plant.c $(CAN_SRC) \
		$(HEADERS) $(PORT_H)
	mkdir -p $(OUT)
	$(CROSS)gcc $(ARM_CFLAGS) $(ARM_LDFLAGS) -o $@ $(SRC) $(PORT) stm32f4/main_peltier.c \
		stm32f4/plant.c $(CAN_SRC)

$(OUT)/tt_pad.elf: $(SRC) $(PORT) stm32f4/main_peltier.c stm32f4/plant.c $(CAN_SRC) \
		$(HEADERS) $(PORT_H)
	mkdir -p $(OUT)
	$(CROSS)gcc $(ARM_CFLAGS) -DTT_ACTIVE_PAD=1 $(ARM_LDFLAGS) -o $@ $(SRC) $(PORT) \
		stm32f4/main_peltier.c stm32f4/plant.c $(CAN_SRC)

$(OUT)/tt_codec.elf: $(SRC) $(PORT) stm32f4/main_codec.c host/tt_codec.c $(HEADERS) $(PORT_H)
	mkdir -p $(OUT)
	$(CROSS)gcc $(ARM_CFLAGS) $(ARM_LDFLAGS) -o $@ $(SRC) $(PORT) stm32f4/main_codec.c \
		host/tt_codec.c

$(OUT)/%.bin: $(OUT)/%.elf
	$(CROSS)objcopy -O binary $< $@
