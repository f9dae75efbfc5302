"""Firmware tests import the board's flat modules the way MicroPython does (firmware/rp2040/)."""

from __future__ import annotations

import sys
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parents[2] / "firmware" / "rp2040"
sys.path.insert(0, str(FIRMWARE_DIR))
