"""Adapters: one reader per device (CAN through python-can, serial through pyserial,
recorded logs), signal maps for foreign DBCs, and recording sessions. See ``base``."""
