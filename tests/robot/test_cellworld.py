"""The cell's layout (station, belt, bins) from a layout file, and the fixed station."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from robot.cellworld import CellLayout
from robot.drivers.conveyor import Conveyor, FixedStation
from robot.errors import RobotError
from robot.layoutfile import MAX_LAYOUT_BYTES, LayoutError, load_layout, parse_layout

GOOD = {
    "station": {"x_m": 0.7, "y_m": 0.1, "surface_z_m": 0.4},
    "belt": {"start_y_m": -1.0, "end_y_m": 1.2, "width_m": 0.4},
    "bins": [
        {"name": "bin-a", "parts": ["a", "b"], "drop_m": [0.3, 0.6, 0.3], "yaw_deg": 90},
        {"name": "reject", "reject": True, "drop_m": [-0.5, -0.5, 0.3]},
    ],
}

TOML = """
[station]
x_m = 0.7
y_m = 0.1
surface_z_m = 0.4

[belt]
start_y_m = -1.0
end_y_m = 1.2
width_m = 0.4

[[bins]]
name = "bin-a"
parts = ["a", "b"]
drop_m = [0.3, 0.6, 0.3]
yaw_deg = 90

[[bins]]
name = "reject"
reject = true
drop_m = [-0.5, -0.5, 0.3]
"""


def test_toml_and_json_give_the_same_layout(tmp_path):
    (tmp_path / "cell.toml").write_text(TOML)
    (tmp_path / "cell.json").write_text(json.dumps(GOOD))
    a, b = load_layout(tmp_path / "cell.toml"), load_layout(tmp_path / "cell.json")
    assert a.bins == b.bins and a.belt == b.belt and a.station_xy_m == b.station_xy_m
    np.testing.assert_allclose(a.station_point, [0.7, 0.1, 0.4])
    assert a.belt_end_y_m == 1.2 and a.belt is not None and a.belt.length_m == pytest.approx(2.2)
    assert a.bin_for("b").name == "bin-a" and a.bin_for("zz").name == "reject"
    assert a.bin_for(None).name == "reject"
    np.testing.assert_allclose(a.bins[0].drop_point, [0.3, 0.6, 0.3])
    assert a.bins[0].yaw_rad == pytest.approx(np.pi / 2)
    assert a.source == str(tmp_path / "cell.toml")


def test_the_default_layout_is_a_station_without_belt_or_bins():
    d = CellLayout()
    assert d.belt is None and d.bins == () and d.bin_for("a") is None
    np.testing.assert_allclose(d.station_point, [0.8, 0.0, 0.45])


def _bad(**changes):
    doc = json.loads(json.dumps(GOOD))
    for path, value in changes.items():
        *keys, last = path.split(".")
        node = doc
        for k in keys:
            node = node[int(k)] if k.isdigit() else node[k]
        if value is KeyError:
            del node[last]
        else:
            node[int(last) if last.isdigit() else last] = value
    return doc


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"station.x_m": float("nan")}, r"station\.x_m must be a finite number, got nan"),
        ({"station.y_m": True}, r"station\.y_m must be a finite number, got True"),
        ({"station.z_m": 1.0}, r"\[station\]: unknown key\(s\) \['z_m'\]"),
        ({"station.surface_z_m": KeyError}, r"\[station\]: missing key\(s\) \['surface_z_m'\]"),
        ({"station.x_m": 9.0}, r"station_xy_m must be \(x, y\) within 3 m"),
        ({"station.y_m": 1.5}, r"the station \(y 1\.5 m\) must lie on the belt"),
        ({"belt.end_y_m": -2.0}, r"belt end_y_m must exceed start_y_m"),
        ({"bins.0.drop_m": [0.3, 0.6]}, r"bins\[0\] \('bin-a'\)\.drop_m must be \[x, y, z\]"),
        (
            {"bins.0.drop_m": [0.3, "x", 0.3]},
            r"bins\[0\] \('bin-a'\)\.drop_m\[1\] must be a finite",
        ),
        ({"bins.0.name": "a b"}, r"bins\[0\] \('a b'\): a bin's name must be a word"),
        ({"bins.1.name": "bin-a"}, r"bin names must be distinct"),
        ({"bins.1.parts": ["a"]}, r"the reject bin 'reject' takes no named parts"),
        ({"bins.1.reject": False}, r"bin 'reject' takes no part"),
        ({"bins.0.reject": "yes"}, r"bins\[0\] \('bin-a'\)\.reject must be true or false"),
        ({"bins.0.size_m": 5.0}, r"size_m must be in \[0\.05, 2\] m, got 5\.0"),
        ({"bins.0.colour": "red"}, r"unknown key\(s\) \['colour'\]"),
        ({"bins": {"name": "x"}}, r"bins must be a list"),
    ],
)
def test_a_bad_layout_names_the_key_and_the_value(changes, message):
    with pytest.raises(LayoutError, match=message) as info:
        parse_layout(_bad(**changes), source="cell.json")
    assert str(info.value).startswith("cell.json: ")


def test_a_part_in_two_bins_and_two_reject_bins_are_refused():
    doc = _bad()
    doc["bins"].append({"name": "bin-b", "parts": ["b"], "drop_m": [0.2, 0.6, 0.3]})
    with pytest.raises(LayoutError, match="part 'b' is sorted into two bins: 'bin-a' and 'bin-b'"):
        parse_layout(doc)
    doc = _bad()
    doc["bins"].append({"name": "r2", "reject": True, "drop_m": [0.2, 0.6, 0.3]})
    with pytest.raises(LayoutError, match=r"at most one reject bin, got \['reject', 'r2'\]"):
        parse_layout(doc)


def test_files_are_bounded_and_must_parse(tmp_path):
    big = tmp_path / "big.json"
    big.write_text(" " * (MAX_LAYOUT_BYTES + 1))
    with pytest.raises(LayoutError, match="more than"):
        load_layout(big)
    with pytest.raises(LayoutError, match=r"must end in \.toml or \.json"):
        load_layout(tmp_path / "cell.yaml")
    with pytest.raises(LayoutError, match="cannot read it"):
        load_layout(tmp_path / "absent.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("[station\nx_m = 1")
    with pytest.raises(LayoutError, match="not valid TOML"):
        load_layout(broken)
    many = _bad()
    many["bins"] = [{"name": f"b{i}", "parts": [f"p{i}"], "drop_m": [0.5, 0.5, 0.3]}
                    for i in range(65)]  # fmt: skip
    with pytest.raises(LayoutError, match="at most 64"):
        parse_layout(many)


def test_a_fixed_station_is_honest_about_what_it_cannot_do():
    station = FixedStation()
    assert isinstance(station, Conveyor) and not station.controllable

    async def go() -> None:
        st = station.status()
        assert (st.mode, st.running, st.speed_m_s, st.travel_m, st.objects) == (
            "index",
            False,
            0.0,
            0.0,
            None,
        )
        with pytest.raises(RobotError, match="station is fixed: there is no belt"):
            await station.start(mode="continuous", speed_m_s=0.1)
        with pytest.raises(RobotError, match="station is fixed"):
            await station.set_running(True)
        with pytest.raises(RobotError, match="cannot run 'continuous'"):
            await station.set_mode("continuous", speed_m_s=0.2)
        assert (await station.stop()).running is False
        await station.halt()
        assert station.halted and station.status().halted
        await station.resume()
        assert not station.halted
        assert station.travel_at(123.0) == 0.0

    asyncio.run(go())
