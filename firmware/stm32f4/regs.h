/* The STM32F405's registers this port touches, by address (RM0090, the
 * STM32F405/415 reference manual, rev. 19: the section is named at each
 * block). No vendor header: a few lines instead of CMSIS and the HAL. */
#ifndef TT_STM32F4_REGS_H
#define TT_STM32F4_REGS_H

#include <stdint.h>

#define REG32(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* RCC (RM0090 6.3) */
#define RCC_BASE 0x40023800u
#define RCC_CR REG32(RCC_BASE + 0x00u)
#define RCC_PLLCFGR REG32(RCC_BASE + 0x04u)
#define RCC_CFGR REG32(RCC_BASE + 0x08u)
#define RCC_AHB1ENR REG32(RCC_BASE + 0x30u)
#define RCC_APB1ENR REG32(RCC_BASE + 0x40u)
#define RCC_APB2ENR REG32(RCC_BASE + 0x44u)
#define RCC_CR_HSIRDY (1u << 1)
#define RCC_CR_HSEON (1u << 16)
#define RCC_CR_HSERDY (1u << 17)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_AHB1ENR_GPIOA (1u << 0)
#define RCC_AHB1ENR_GPIOB (1u << 1)
#define RCC_APB1ENR_USART2 (1u << 17)
#define RCC_APB1ENR_CAN1 (1u << 25)
#define RCC_APB2ENR_USART1 (1u << 4)

/* Flash interface (RM0090 3.9) */
#define FLASH_ACR REG32(0x40023C00u)

/* GPIO (RM0090 8.4) */
#define GPIOA_BASE 0x40020000u
#define GPIOB_BASE 0x40020400u
#define GPIO_MODER(base) REG32((base) + 0x00u)
#define GPIO_OSPEEDR(base) REG32((base) + 0x08u)
#define GPIO_PUPDR(base) REG32((base) + 0x0Cu)
#define GPIO_AFRL(base) REG32((base) + 0x20u)
#define GPIO_AFRH(base) REG32((base) + 0x24u)

/* USART (RM0090 30.6) */
#define USART1_BASE 0x40011000u
#define USART2_BASE 0x40004400u
#define USART_SR(base) REG32((base) + 0x00u)
#define USART_DR(base) REG32((base) + 0x04u)
#define USART_BRR(base) REG32((base) + 0x08u)
#define USART_CR1(base) REG32((base) + 0x0Cu)
#define USART_CR2(base) REG32((base) + 0x10u)
#define USART_CR3(base) REG32((base) + 0x14u)
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE (1u << 13)
#define USART1_IRQN 37u
#define USART2_IRQN 38u

/* bxCAN (RM0090 32.9) */
#define CAN1_BASE 0x40006400u
#define CAN_MCR REG32(CAN1_BASE + 0x000u)
#define CAN_MSR REG32(CAN1_BASE + 0x004u)
#define CAN_TSR REG32(CAN1_BASE + 0x008u)
#define CAN_RF0R REG32(CAN1_BASE + 0x00Cu)
#define CAN_BTR REG32(CAN1_BASE + 0x01Cu)
#define CAN_TIR(n) REG32(CAN1_BASE + 0x180u + 0x10u * (n))
#define CAN_TDTR(n) REG32(CAN1_BASE + 0x184u + 0x10u * (n))
#define CAN_TDLR(n) REG32(CAN1_BASE + 0x188u + 0x10u * (n))
#define CAN_TDHR(n) REG32(CAN1_BASE + 0x18Cu + 0x10u * (n))
#define CAN_RI0R REG32(CAN1_BASE + 0x1B0u)
#define CAN_RDT0R REG32(CAN1_BASE + 0x1B4u)
#define CAN_RDL0R REG32(CAN1_BASE + 0x1B8u)
#define CAN_RDH0R REG32(CAN1_BASE + 0x1BCu)
#define CAN_FMR REG32(CAN1_BASE + 0x200u)
#define CAN_FM1R REG32(CAN1_BASE + 0x204u)
#define CAN_FS1R REG32(CAN1_BASE + 0x20Cu)
#define CAN_FFA1R REG32(CAN1_BASE + 0x214u)
#define CAN_FA1R REG32(CAN1_BASE + 0x21Cu)
#define CAN_FR1(n) REG32(CAN1_BASE + 0x240u + 8u * (n))
#define CAN_FR2(n) REG32(CAN1_BASE + 0x244u + 8u * (n))

/* Cortex-M4 core (ARMv7-M ARM B3.3, B3.4) */
#define SYST_CSR REG32(0xE000E010u)
#define SYST_RVR REG32(0xE000E014u)
#define SYST_CVR REG32(0xE000E018u)
#define SYST_CSR_ENABLE (1u << 0)
#define SYST_CSR_TICKINT (1u << 1)
#define SYST_CSR_CLKSOURCE (1u << 2)
#define NVIC_ISER(n) REG32(0xE000E100u + 4u * (n))
#define NVIC_ICER(n) REG32(0xE000E180u + 4u * (n))
#define NVIC_ISPR(n) REG32(0xE000E200u + 4u * (n))
#define SCB_CPACR REG32(0xE000ED88u)
#define SCB_ICSR REG32(0xE000ED04u) /* ARMv7-M B3.2.4 */
#define SCB_ICSR_PENDSTSET (1u << 26)
#define SCB_ICSR_PENDSTCLR (1u << 25)
#define SCB_VTOR REG32(0xE000ED08u)

#endif
