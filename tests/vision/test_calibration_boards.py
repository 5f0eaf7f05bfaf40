"""Board definitions and the text forms the CLI and the API accept."""

import re

import numpy as np
import pytest

from vision.calibration import (
    CharucoBoard,
    Chessboard,
    board_from_dict,
    parse_board_size,
    parse_length_m,
)


@pytest.mark.parametrize(
    ("text", "size"), [("9x6", (9, 6)), (" 24X17 ", (24, 17)), ("7×5", (7, 5))]
)
def test_board_size_parses(text, size):
    assert parse_board_size(text) == size


@pytest.mark.parametrize("text", ["9by6", "9", "x6", "9x6x2", "-9x6", ""])
def test_bad_board_size_names_the_value(text):
    with pytest.raises(ValueError, match=f"board must look like 9x6, got {text!r}"):
        parse_board_size(text)


@pytest.mark.parametrize(
    ("text", "metres"),
    [("25mm", 0.025), ("2.5cm", 0.025), ("0.025m", 0.025), ("25", 0.025), ("15 mm", 0.015)],
)
def test_lengths_parse_with_units_and_plain_numbers_are_millimetres(text, metres):
    assert parse_length_m(text) == pytest.approx(metres)


@pytest.mark.parametrize("text", ["abc", "25in", "0mm", "-3mm", "mm"])
def test_bad_length_names_the_value(text):
    with pytest.raises(
        ValueError, match=f"square must be a positive length like 25mm or 0.025m, got {text!r}"
    ):
        parse_length_m(text)


def test_chessboard_geometry():
    b = Chessboard(9, 6, 0.025)
    P = b.object_points()
    assert P.shape == (54, 3) and b.n_corners == 54 and b.pattern_size == (9, 6)
    np.testing.assert_allclose(P[1] - P[0], [0.025, 0, 0])  # along a row: +x
    np.testing.assert_allclose(P[9] - P[0], [0, 0.025, 0])  # next row: +y
    assert b.orientation_unique
    assert not Chessboard(8, 6, 0.02).orientation_unique  # rows + cols even: 180 deg ambiguous
    assert not Chessboard(7, 7, 0.02).orientation_unique  # square


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((2, 6, 0.02), "cols must be an integer in [3, 100] (inner corners), got 2"),
        ((9, 6, 0.0), "square_m must be a length in [0.001, 1] m, got 0.0"),
        ((9, 6, float("nan")), "square_m must be a length in"),
    ],
)
def test_bad_chessboard(args, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        Chessboard(*args)


def test_charuco_geometry_and_validation():
    b = CharucoBoard(7, 5, 0.04, 0.03)
    P = b.object_points()
    assert P.shape == (24, 3) and b.n_corners == 24 and b.orientation_unique
    np.testing.assert_allclose(P[0], [0, 0, 0])  # the first inner corner is the origin
    np.testing.assert_allclose(P[1] - P[0], [0.04, 0, 0])
    cv_pts = np.asarray(b.to_cv().getChessboardCorners(), dtype=np.float64)  # origin: outer corner
    np.testing.assert_allclose(P, cv_pts - [0.04, 0.04, 0.0], atol=1e-7)
    with pytest.raises(ValueError, match="marker_m must be smaller than square_m"):
        CharucoBoard(7, 5, 0.04, 0.04)
    with pytest.raises(ValueError, match=r"dictionary must be one of .* got 'DICT_9X9'"):
        CharucoBoard(7, 5, 0.04, 0.03, "DICT_9X9")
    with pytest.raises(ValueError, match="needs 200 markers but DICT_4X4_50 has 50"):
        CharucoBoard(20, 20, 0.04, 0.03, "DICT_4X4_50")


@pytest.mark.parametrize(
    "board", [Chessboard(9, 6, 0.025), CharucoBoard(7, 5, 0.04, 0.03, legacy=True)]
)
def test_board_dict_round_trip(board):
    assert board_from_dict(board.as_dict()) == board


@pytest.mark.parametrize(
    ("d", "message"),
    [
        ({"type": "chessboard", "cols": 9}, "board of type 'chessboard' needs the field 'rows'"),
        ({"type": "hexagon"}, "board type must be 'chessboard' or 'charuco', got 'hexagon'"),
        ("9x6", "board must be an object, got '9x6'"),
    ],
)
def test_bad_board_dict(d, message):
    with pytest.raises(ValueError, match=message):
        board_from_dict(d)
