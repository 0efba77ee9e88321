"""Serial (UART to nRF52 BLE relay) link to the frog robot, and a robot emulator for the digital
twin.
"""
