"""Make the calibration board's texture: a chessboard for ``twin calibrate`` in the twin.

Run from anywhere: ``python models/make_board.py``. The output is drawn with numpy only and is
byte-identical on every run; it is committed, so loading ``scenes/calibration_board.xml`` never
needs this script.

The board (``BOARD`` below) is the kind printed for OpenCV calibration: 10 x 7 squares of
0.06 m (9 x 6 inner corners, what ``twin calibrate --pattern 9x6`` looks for) on a white margin
of one square all round, so the whole printed sheet is 12 x 9 squares = 0.72 m x 0.54 m. The
texture has 40 pixels per square: at the twin's 1-2 m a square covers 11-23 camera pixels, so
the texture (480 x 360) is never magnified much and its edges stay sharp.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twin.sim.render import write_png

HERE = Path(__file__).resolve().parent
OUT = HERE / "textures" / "calibration_board.png"

SQUARES = (10, 7)  # columns, rows of squares
SQUARE_M = 0.06  # side of one square, metres
MARGIN = 1  # white squares round the pattern
PX_PER_SQUARE = 40
BLACK, WHITE = 20, 245  # printed black is not 0, paper not 255


def board() -> np.ndarray:
    """The sheet, H x W x 3 uint8 RGB, top-left square black."""
    cols, rows = SQUARES
    total = (rows + 2 * MARGIN, cols + 2 * MARGIN)
    sheet = np.full((total[0] * PX_PER_SQUARE, total[1] * PX_PER_SQUARE), WHITE, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = (r + MARGIN) * PX_PER_SQUARE, (c + MARGIN) * PX_PER_SQUARE
                sheet[y : y + PX_PER_SQUARE, x : x + PX_PER_SQUARE] = BLACK
    return np.repeat(sheet[..., None], 3, axis=2)


def main() -> None:
    write_png(OUT, board(), compression=9)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
