"""Firmware in the loop: an AVR firmware image run cycle by cycle in simavr (``twin.avr.core``)."""
