"""Adapters: one reader per device (CAN through python-can, serial through pyserial,
recorded logs) and signal maps for foreign DBCs. See ``base``; per-source health: ``health``."""
