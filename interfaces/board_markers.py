"""Where the ArUco markers sit on a whiteboard: the contract between the board (sim or real) and perception.

Four markers of OpenCV's ``DICT_4X4_50``, ids 0-3, one in each corner of
the board, printed upright when the board is seen from the front (its z
axis towards the viewer, its y axis up):

====  ===================
 id   corner
====  ===================
 0    bottom-left (origin)
 1    bottom-right
 2    top-right
 3    top-left
====  ===================

Each marker is a square of side :data:`MARKER_SIDE_M` (black border
included) whose outer corner is :data:`MARKER_INSET_M` from both board
edges. That is the cell's board (:data:`DEFAULT_LAYOUT`); a real board may
carry markers of any OpenCV ArUco dictionary or AprilTag family, with other
ids, size and inset: a :class:`MarkerLayout` (``[perception.board]``
``dictionary``, ``marker_ids``, ``marker_side_m``, ``marker_inset_m``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ARUCO_DICTIONARY = "DICT_4X4_50"
MARKER_IDS: tuple[int, int, int, int] = (0, 1, 2, 3)
MARKER_SIDE_M = 0.06
MARKER_INSET_M = 0.01
#: Cells of one marker including its black border (4x4 bits + 1 border cell each side).
MARKER_CELLS = 6


#: OpenCV's predefined dictionaries (``cv2.aruco.DICT_*``) -> how many markers each holds.
DICTIONARIES = {
    **{f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
    "DICT_ARUCO_ORIGINAL": 1024, "DICT_ARUCO_MIP_36h12": 250,
    "DICT_APRILTAG_16h5": 30, "DICT_APRILTAG_25h9": 35, "DICT_APRILTAG_36h10": 2320, "DICT_APRILTAG_36h11": 587,
}
#: The board corners in the order :attr:`MarkerLayout.ids` names them.
CORNERS = ("bottom-left", "bottom-right", "top-right", "top-left")


@dataclass(frozen=True)
class MarkerLayout:
    """The four corner markers of a board: OpenCV dictionary name, their ids by corner (bottom-left,
    bottom-right, top-right, top-left, seen from the front, upright), side [m] (black border included) and the
    inset of each marker's outer corner from both board edges [m]. ValueError names a bad value."""

    dictionary: str = ARUCO_DICTIONARY
    ids: tuple[int, int, int, int] = MARKER_IDS
    side_m: float = MARKER_SIDE_M
    inset_m: float = MARKER_INSET_M

    def __post_init__(self) -> None:
        if self.dictionary not in DICTIONARIES:
            raise ValueError(f"dictionary must be one of OpenCV's {sorted(DICTIONARIES)}, got {self.dictionary!r}")
        ids = tuple(self.ids)
        n = DICTIONARIES[self.dictionary]
        if (len(ids) != 4 or len(set(ids)) != 4
                or not all(isinstance(i, int) and not isinstance(i, bool) and 0 <= i < n for i in ids)):
            raise ValueError(f"marker ids must be 4 different integers in [0, {n}) for {self.dictionary} "
                             f"({', '.join(CORNERS)}), got {self.ids!r}")
        object.__setattr__(self, "ids", ids)

    def corner_index(self, marker_id: int) -> int:
        """0..3: which corner of :data:`CORNERS` the marker ``marker_id`` marks."""
        return self.ids.index(marker_id)

    @property
    def centre_inset_m(self) -> float:
        """A marker's centre lies this far [m] from its two nearest board edges."""
        return self.inset_m + self.side_m / 2

    def origins(self, board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
        """Bottom-left corner (2,) [m] of each marker in the board frame, by id."""
        w, h = board_size_m
        a, s = self.inset_m, self.side_m
        spots = ([a, a], [w - a - s, a], [w - a - s, h - a - s], [a, h - a - s])
        return {mid: np.array(xy, float) for mid, xy in zip(self.ids, spots)}

    def corners(self, board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
        """Corners (4, 2) [m] of each marker in the board frame, in OpenCV's order, by id.

        OpenCV's ArUco detector returns the corners of an upright marker as
        top-left, top-right, bottom-right, bottom-left; with the board's y axis
        up, that is (x0, y0+s), (x0+s, y0+s), (x0+s, y0), (x0, y0).
        """
        s = self.side_m
        return {mid: np.array([[x0, y0 + s], [x0 + s, y0 + s], [x0 + s, y0], [x0, y0]])
                for mid, (x0, y0) in self.origins(board_size_m).items()}


#: The cell's own board (the simulator draws it).
DEFAULT_LAYOUT = MarkerLayout()


def marker_origins_board(board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
    """Bottom-left corner (2,) [m] of each marker of :data:`DEFAULT_LAYOUT` in the board frame."""
    return DEFAULT_LAYOUT.origins(board_size_m)


def marker_corners_board(board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
    """Corners (4, 2) [m] of each marker of :data:`DEFAULT_LAYOUT` in the board frame, in OpenCV's order."""
    return DEFAULT_LAYOUT.corners(board_size_m)
