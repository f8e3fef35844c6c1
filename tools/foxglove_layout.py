"""Write the shipped Foxglove layout, ``configs/foxglove/vdps-layout.json``, from
``vdps_hil.app.foxglove_layout.build_layout`` (run after changing the layout; a test holds the
file equal to it).

    .venv/bin/python tools/foxglove_layout.py [--check]
"""

from __future__ import annotations

import sys

from vdps_hil.app.foxglove_layout import LAYOUT_PATH, layout_json


def main(argv: list[str]) -> int:
    text = layout_json()
    if "--check" in argv:
        same = LAYOUT_PATH.is_file() and LAYOUT_PATH.read_text() == text
        print(f"{LAYOUT_PATH}: {'up to date' if same else 'differs from build_layout()'}")
        return 0 if same else 1
    LAYOUT_PATH.parent.mkdir(parents=True, exist_ok=True)
    LAYOUT_PATH.write_text(text)
    print(f"wrote {LAYOUT_PATH} ({len(text)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
