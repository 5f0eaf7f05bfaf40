"""The operator's path, end to end, with only what a new user has.

``visioncell serve`` runs as a process on the simulated cell with a fresh database; the
token is the one it prints at start-up (read from its output, as a user copies it).  In
headless Chromium the Models page's wizard creates and teaches two 3D parts and a wheel,
each for the rounds the wizard itself guides it to (the rounds its kind needs to be
recognised at any yaw; the test never sets a number of its own), the Inspection page
inspects once and then runs a sorted run of six objects the test puts on the belt at random
yaws (a seeded draw over the full circle) through the simulator's REST controls, as a user
of the demo does: each taught part must land in its own bin and the untrained one in the
reject bin, as the Inspection page, the Reports drill-down and the CSV export all say, with
durations that match the wall time.  Then the same through the CLI as a subprocess
(``models add``, ``models teach`` for every round it prints the command of, ``inspect
once``, ``inspect run --sort --count N`` with bins and durations, ``report --csv``).

Nothing is set up behind the product's back: no catalogue geometry, no database access, no
benchmark helper.  The simulator's truth is read only to check where objects landed.
The tests of this module run in order and share one server.
"""

from __future__ import annotations

import csv
import io
import math
import random
import re
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import httpx
import pytest

from tests.e2e.conftest import start_server

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

VIEWPORT = {"width": 1280, "height": 800}
PART_A = "gear-housing"  # a 3D part: top and side views
PART_B = "valve-block"  # another 3D part
WHEEL = "wheel-7spoke-curved"  # a wheel: top views
UNTRAINED = "oil-filter"  # never taught: must go to the reject bin
CLI_PART = "junction-box"  # a 3D part taught through the CLI
#: The sorted run: taught parts (the 3D ones twice) and the untrained one, in belt order.
RUN = (PART_A, WHEEL, PART_B, UNTRAINED, PART_B, PART_A)
#: The objects' yaws on the belt: a seeded draw over the full circle (degrees).
YAWS = random.Random(30).sample(range(-180, 180), len(RUN) + 2)
#: Between objects on the belt, as on the demo belt (more than the top view sees of it).
SPACING_M = 0.42
#: Bounds that only end a hang: the machine may be loaded by other work.
TEACH_S = 1500.0
RUN_S = 2400.0
HANG_MS = 180_000


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    s = start_server(
        tmp_path_factory.mktemp("user-path"),
        ready_s=600.0,  # MuJoCo and the first renders start slowly on a busy machine
        VISIONCELL_DRIVER="sim",
        VISIONCELL_CAMERA="sim",
        VISIONCELL_SIM_DEMO="false",
        VISIONCELL_TIME_SCALE="10",
    )
    yield s
    s.stop()


@pytest.fixture(scope="module")
def token(cell) -> str:
    """The token ``visioncell serve`` printed: the line after '... token (user ...):'."""
    lines = cell.log.read_text().splitlines()
    # What the README's "What you will see" shows, line for line, with nothing between.
    at = next(k for k, line in enumerate(lines) if line.startswith("VisionCell "))
    banner = lines[at : at + 9]
    viser = cell.viser.rsplit(":", 1)[1]
    assert re.fullmatch(r"VisionCell \S+  cell=cell-1 driver=sim camera=sim", banner[0]), banner
    assert banner[1:4] == [f"  console   {cell.base}/",
                           f"  REST API  {cell.base}/api   (docs: {cell.base}/docs)",
                           f"  3D view   http://127.0.0.1:{viser}/"], banner  # fmt: skip
    assert banner[4] == "  engineer token (user 'engineer', valid until the next start):", banner
    assert re.fullmatch(r"  vc_\S+", banner[5]), banner
    assert banner[6:] == ["  (loopback demo: an engineer's; in production or on a network address,",
                          "  the start-up token is an operator's)", "Press Ctrl-C to stop."], banner  # fmt: skip
    for k, line in enumerate(lines[:-1]):
        if re.search(r"\btoken \(user '[^']+'", line):
            assert "engineer token" in line, line  # a loopback demo: one token for the tour
            return lines[k + 1].strip()
    raise AssertionError(f"no start-up token in the output of serve:\n{chr(10).join(lines)}")


@pytest.fixture(scope="module")
def auth(token) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture(scope="module")
def page(browser, cell, token):
    p = browser.new_page(viewport=VIEWPORT, accept_downloads=True)
    # Every wait of the page without a bound of its own only ends a hang (Playwright's
    # default, 30 s, is short of what a loaded machine takes to answer a click).
    p.set_default_timeout(HANG_MS)
    p.goto(cell.base + "/#models")
    p.fill("#token", token)
    p.click("#login")
    p.wait_for_selector("#models-page")
    yield p
    p.close()


# -- helpers: REST with the printed token, the simulator's controls -------------------------
def _get(cell, auth, path: str) -> dict:
    r = httpx.get(f"{cell.base}/api{path}", headers=auth, timeout=60)
    assert r.status_code == 200, (path, r.status_code, r.text)
    return r.json()


def _station_m(cell, auth) -> float:
    return float(_get(cell, auth, "/sim/conveyor")["conveyor"]["station_s_m"])


def _clear_belt(cell, auth) -> None:
    """Stop the belt in index mode and take every object off it (the wizard's 'clear')."""
    r = httpx.post(f"{cell.base}/api/sim/conveyor", headers=auth, timeout=60,
                   json={"running": False, "mode": "index", "dwell_s": None})  # fmt: skip
    assert r.status_code == 200, r.text
    for o in _get(cell, auth, "/sim/objects?limit=100")["data"]:
        r = httpx.delete(f"{cell.base}/api/sim/objects/{o['id']}", headers=auth, timeout=60)
        assert r.status_code == 204, r.text


def _put(cell, auth, name: str, along_m: float, yaw_deg: float = 0.0) -> int:
    r = httpx.post(f"{cell.base}/api/sim/objects", headers=auth, timeout=60,
                   json={"name": name, "position_along_belt_m": along_m, "lateral_m": 0.0,
                         "yaw_rad": math.radians(yaw_deg)})  # fmt: skip
    assert r.status_code == 201, r.text
    return int(r.json()["object"]["id"])


def _rows(cell, auth) -> list[dict]:
    return sorted(_get(cell, auth, "/inspections?limit=100")["data"], key=lambda r: r["id"])


def _when(text: str) -> float:
    t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    if t.tzinfo is None:
        from datetime import UTC

        t = t.replace(tzinfo=UTC)
    return t.timestamp()


def _bin_of(cell, auth, model: str) -> str:
    """The bin the cell sorts this model's part into (its part's own bin)."""
    m = next(m for m in _get(cell, auth, "/models?limit=100")["data"] if m["name"] == model)
    return f"bin-{m['part']}"


def _cli(cell, *args: str, timeout: float = TEACH_S) -> subprocess.CompletedProcess[str]:
    r = subprocess.run([sys.executable, "-m", "backend.cli", *args], capture_output=True,
                       text=True, env=cell.env, timeout=timeout)  # fmt: skip
    assert r.returncode == 0, (args, r.returncode, r.stdout, r.stderr)
    return r


# -- 1. the Models page: create and teach two 3D parts and a wheel in the wizard ------------
def _teach_in_wizard(page, cell, auth, name: str, kind: str) -> dict:
    """Create ``name`` and teach it round after round as the wizard guides, until it says
    every round is taught; returns the rounds it guided to and the last result's text."""
    page.goto(page.url.split("#")[0] + "#models")
    page.wait_for_selector("#models-page")
    page.fill("#new-model-name", name)
    page.select_option("#new-model-kind", kind)
    page.click("#new-model")
    # The user picks the new model's row (the list may still be refreshing after a teach).
    row = f'#models-table tr[data-name="{name}"]'
    page.wait_for_selector(row)
    page.click(row)
    page.wait_for_function(
        f"() => document.querySelector('#model-title').textContent.startsWith('{name} (')"
    )
    page.wait_for_selector(f"{row}.selected")
    page.wait_for_selector("#sim-clear:not([hidden])")
    # The rounds are the wizard's: what the model's kind needs, as the server says.
    model = next(m for m in _get(cell, auth, "/models?limit=100")["data"] if m["name"] == name)
    rounds = int(page.input_value("#teach-rounds"))
    assert rounds == model["rounds"]["recommended"], (rounds, model["rounds"])
    assert f"needs {rounds} round" in page.text_content("#teach-rounds-why")
    page.wait_for_function(
        f"() => document.querySelector('#teach-start').textContent.includes('1 of {rounds}')"
    )
    page.click("#sim-clear")
    page.wait_for_function(
        "() => document.querySelector('#teach-message').textContent.includes('station cleared')"
    )
    texts = []
    # The last teach job's state line: each round's job has its own id.
    before = page.text_content("#teach-state") or ""
    for k in range(rounds):
        assert f"Round {k + 1} of {rounds}" in page.text_content("#teach-round")
        if k == 0:  # the first round grabs the empty station, then waits for the object
            page.select_option("#teach-background", "grab")
            page.click("#teach-start")
            page.wait_for_selector("#teach-place.attention", timeout=TEACH_S * 1000)
            page.select_option("#place-name", name)
            page.click("#place-object")
        else:  # later rounds: the wizard turns the object to the round's yaw, then teaches
            page.click("#place-object")
            page.wait_for_function(
                "() => document.querySelector('#teach-message').textContent.includes('placed')"
            )
            page.click("#teach-start")
        page.wait_for_function(
            "(before) => { const t = document.querySelector('#teach-state').textContent;"
            " return t !== before && /teach job \\S+: (done|failed|cancelled|interrupted)/.test(t); }",
            arg=before,
            timeout=TEACH_S * 1000,
        )
        state = before = page.text_content("#teach-state")
        assert state.endswith("done"), (state, page.text_content("#teach-message"))
        texts.append(page.text_content("#teach-result"))
    page.wait_for_function(
        "() => document.querySelector('#teach-round').textContent.startsWith('All ')"
    )
    return {"rounds": rounds, "text": texts[-1], "texts": texts}


@pytest.mark.timeout(5400)  # a bound on a hang only: slow on a loaded machine
def test_teach_two_parts_and_a_wheel_in_the_wizard(cell, auth, page):
    assert _get(cell, auth, "/models")["count"] == 0  # a fresh database
    taught = {}
    for name, kind in ((PART_A, "3d"), (PART_B, "3d"), (WHEEL, "2d")):
        t0 = time.monotonic()
        taught[name] = _teach_in_wizard(page, cell, auth, name, kind)
        print(f"{name}: {taught[name]['rounds']} rounds in {time.monotonic() - t0:.0f} s")
        height = page.text_content("#teach-height")
        assert "Part height" in height and "not known" not in height, height
        # The last round chose the threshold, and it is never 0.
        thr = re.search(r"Threshold in force: (\d+\.\d+)", taught[name]["text"])
        assert thr and float(thr.group(1)) > 0.0, taught[name]["text"]
    # The wizard guided the 3D parts through more rounds than the wheel.
    assert taught[PART_A]["rounds"] == taught[PART_B]["rounds"] > taught[WHEEL]["rounds"] >= 1
    assert "deferred to the last round" in taught[PART_A]["texts"][0]
    models = {m["name"]: m for m in _get(cell, auth, "/models?limit=100")["data"]}
    assert set(models) == {PART_A, PART_B, WHEEL}
    for m in models.values():
        assert m["views"] > 0 and m["height_m"] is not None, m
        assert m["geometry_source"] == "measured", m
        assert m["rounds"]["taught"] == m["rounds"]["recommended"], m
    assert _get(cell, auth, "/recognition/settings")["global_threshold"] > 0.0


# -- 2. the Inspection page: inspect once -------------------------------------------------
@pytest.mark.timeout(1800)  # a bound on a hang only: slow on a loaded machine
def test_inspect_once_from_the_inspection_page(cell, auth, page):
    # The wheel taught last is still at the station.
    page.goto(page.url.split("#")[0] + "#inspection")
    page.wait_for_selector("#inspection-page")
    page.click("#insp-once")
    page.wait_for_selector("#filmstrip .frame", timeout=TEACH_S * 1000)
    rows = _rows(cell, auth)
    assert len(rows) == 1, rows
    assert rows[0]["decision"] == "recognized" and rows[0]["model"] == WHEEL, rows[0]["reason"]
    page.wait_for_function(
        f"() => document.querySelector('#live-label').textContent.startsWith('#{rows[0]['id']} ')"
    )
    assert WHEEL in page.text_content("#live-label")


# -- 3. a continuous sorted run of six objects at random yaws ------------------------------
@pytest.mark.timeout(3600)  # a bound on a hang only: slow on a loaded machine
def test_sorted_run_puts_each_part_in_its_bin(cell, auth, page):
    _clear_belt(cell, auth)
    conveyor = _get(cell, auth, "/sim/conveyor")["conveyor"]
    station, length = float(conveyor["station_s_m"]), float(conveyor["length_m"])
    # As the demo belt holds them: the first at the station, the others upstream in this
    # order, the belt's own length apart at most (objects leaving it come back at its entry).
    assert SPACING_M * len(RUN) <= length, (SPACING_M, length)
    for k, (name, yaw) in enumerate(zip(RUN, YAWS, strict=False)):
        _put(cell, auth, name, (station - SPACING_M * k) % length, yaw)
    before = {r["id"] for r in _rows(cell, auth)}
    page.goto(page.url.split("#")[0] + "#inspection")
    page.wait_for_selector("#inspection-page")
    page.check("#insp-sort")
    page.fill("#insp-count", str(len(RUN)))
    page.click("#insp-run")
    page.wait_for_selector("#belt-start:not([disabled])")
    page.click("#belt-start")
    # Each new row's first sighting bounds its wall time (polled often; the bound ends a hang).
    seen: dict[int, float] = {}
    t0 = time.monotonic()
    while len(seen) < len(RUN):
        assert time.monotonic() - t0 < RUN_S, f"the run stored {len(seen)} rows in {RUN_S} s"
        for r in _rows(cell, auth):
            if r["id"] not in before and r["id"] not in seen:
                seen[r["id"]] = time.time()
        time.sleep(0.5)
    rows = [r for r in _rows(cell, auth) if r["id"] in seen]
    got = [(r["decision"], r["model"], r["reason"]) for r in rows]
    assert [r["model"] for r in rows] == [n if n != UNTRAINED else None for n in RUN], got
    assert [r["decision"] for r in rows] == [
        "unknown" if n == UNTRAINED else "recognized" for n in RUN
    ], got
    bins = {n: "reject" if n == UNTRAINED else _bin_of(cell, auth, n) for n in set(RUN)}
    assert len(set(bins.values())) == 4, bins  # each taught part in its own bin
    want = [bins[n] for n in RUN]
    for r, b in zip(rows, want, strict=True):
        assert r["pick_outcome"]["bin"] == b, (r["id"], r["pick_outcome"], r["pick"])
        assert r["pick_outcome"]["outcome"] == ("rejected" if b == "reject" else "placed"), r
        # The stored duration is the inspection's own wall time: its start and end as
        # stored, the end no later than the test first saw the row (polled every 0.5 s; a
        # loaded machine may take seconds to answer).
        start, end = _when(r["started_at"]), _when(r["finished_at"])
        wall = end - start
        assert abs(r["duration_s"] - wall) <= max(2.0, 0.05 * wall), (
            r["id"],
            r["duration_s"],
            wall,
        )
        assert -1.0 <= seen[r["id"]] - end <= 60.0, (r["id"], seen[r["id"]], end)
    # The simulator's truth, read only to check: each row is the object put there, in
    # belt order at its yaw, and every one of them was picked off the belt.
    truth = [(r["truth"] or {}) for r in rows]
    assert [t.get("name") for t in truth] == list(RUN), truth
    for t, yaw in zip(truth, YAWS, strict=False):
        assert abs(math.remainder(math.radians(yaw) - t["yaw_rad"], math.tau)) < 0.05, (t, yaw)
    assert _get(cell, auth, "/sim/objects?limit=100")["count"] == 0

    # The Inspection page: each row's bin and pick outcome, from the filmstrip.
    page.wait_for_function(
        f"() => document.querySelectorAll('#filmstrip .frame').length >= {len(seen) + 1}",
        timeout=120_000,
    )
    for r, b in zip(rows, want, strict=True):
        page.click(f'#filmstrip .frame[data-id="{r["id"]}"]')
        page.wait_for_function(
            f"() => document.querySelector('#live-label').textContent.startsWith('#{r['id']} ')"
        )
        assert page.get_attribute("#live-pick", "data-bin") == b
        assert page.get_attribute("#live-pick", "data-outcome") == r["pick_outcome"]["outcome"]
        assert b in page.text_content("#live-pick")

    # The Reports page: the table's bin column and the drill-down of each row.
    page.goto(page.url.split("#")[0] + "#reports")
    page.wait_for_selector(f'#rep-table tbody tr[data-id="{rows[-1]["id"]}"]')
    for r, b in zip(rows, want, strict=True):
        tr = f'#rep-table tbody tr[data-id="{r["id"]}"]'
        assert page.text_content(f"{tr} .rep-bin").strip() == b
        page.click(tr)
        page.wait_for_function(
            f"() => document.querySelector('#rep-detail-title').textContent"
            f".startsWith('Inspection #{r['id']}:')"
        )
        assert page.get_attribute("#rep-detail-pick", "data-bin") == b
        assert (
            page.get_attribute("#rep-detail-pick", "data-outcome") == r["pick_outcome"]["outcome"]
        )
        shown = re.search(r"([0-9.]+) s$", page.text_content("#rep-detail-reason").strip())
        assert shown and abs(float(shown.group(1)) - r["duration_s"]) < 0.011, shown

    # The CSV export (downloaded from the page): bins, outcomes and durations.
    with page.expect_download() as dl:
        page.click("#rep-export")
    table = {
        int(t["id"]): t for t in csv.DictReader(io.StringIO(Path(dl.value.path()).read_text()))
    }
    for r, b in zip(rows, want, strict=True):
        got = table[r["id"]]
        assert (got["bin"], got["pick"]) == (b, r["pick_outcome"]["outcome"]), got
        assert abs(float(got["duration_s"]) - r["duration_s"]) < 1e-3, got


# -- 4. the same through the CLI ----------------------------------------------------------
def _turn_at_station(cell, auth, name: str, yaw_deg: float) -> None:
    """What a user of the demo does between rounds: the object at the station, turned."""
    for o in _get(cell, auth, "/sim/objects?limit=100")["data"]:
        r = httpx.delete(f"{cell.base}/api/sim/objects/{o['id']}", headers=auth, timeout=60)
        assert r.status_code == 204, r.text
    _put(cell, auth, name, _station_m(cell, auth), yaw_deg)


@pytest.mark.timeout(5400)  # a bound on a hang only: slow on a loaded machine
def test_the_same_through_the_cli(cell, token, auth, tmp_path):
    url = ["--token", token, "--url", cell.base]
    r = _cli(cell, "models", "add", CLI_PART, "--kind", "3d", timeout=300)
    assert r.stdout.strip().splitlines()[-1].isdigit(), r.stdout

    # As the README says: the first teach grabs the empty station's backgrounds and then
    # waits for the object, which the user puts there when the command says so; each teach
    # then prints the next round's command and the yaw to turn the object to.
    _clear_belt(cell, auth)
    cmd = [sys.executable, "-m", "backend.cli", "models", "teach", CLI_PART, "--wait", "600", *url]
    err_log = cell.log.with_name("cli-teach.err")
    placed = False
    with (
        err_log.open("w") as err_file,
        subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=err_file, text=True, env=cell.env
        ) as proc,
    ):
        out: list[str] = []
        for line in proc.stdout:  # the test's timeout bounds a hang
            out.append(line)
            if "waiting for an object" in line and not placed:
                _put(cell, auth, CLI_PART, _station_m(cell, auth))
                placed = True
        code = proc.wait()
    err = err_log.read_text()
    assert code == 0, ("".join(out), err)
    assert placed and "Traceback" not in err, ("".join(out), err)
    text = "".join(out)
    rounds = 1
    while "rounds a 3d model needs are taught" not in text:
        turn = re.search(r"turn the object to (-?[0-9.]+) deg", text)
        nxt = re.search(r"^  visioncell (models teach .+)$", text, re.MULTILINE)
        assert turn and nxt, text
        _turn_at_station(cell, auth, CLI_PART, float(turn.group(1)))
        args = nxt.group(1).replace("--token TOKEN", "").split()
        text = _cli(cell, *args, *url).stdout
        rounds += 1
        assert rounds <= 12, text
    m = next(m for m in _get(cell, auth, "/models?limit=100")["data"] if m["name"] == CLI_PART)
    assert m["views"] > 0 and m["height_m"] is not None, m
    assert rounds == m["rounds"]["taught"] == m["rounds"]["recommended"], (rounds, m)

    r = _cli(cell, "inspect", "once", "--sort", *url)
    last = r.stdout.strip().splitlines()[-1]
    assert re.match(rf"#\d+ recognized {re.escape(CLI_PART)} ", last), r.stdout
    assert f"placed in {_bin_of(cell, auth, CLI_PART)}" in last, last

    _clear_belt(cell, auth)
    station = _station_m(cell, auth)
    yaws = YAWS[len(RUN) :]
    _put(cell, auth, CLI_PART, station - 0.25, yaws[0])
    _put(cell, auth, UNTRAINED, station - 0.25 - SPACING_M, yaws[1])
    r = httpx.post(f"{cell.base}/api/belt", headers=auth, timeout=60, json={"running": True})
    assert r.status_code == 200, r.text
    r = _cli(cell, "inspect", "run", "--sort", "--count", "2", *url, timeout=RUN_S)
    lines = [ln for ln in r.stdout.splitlines() if re.match(r"#\d+ ", ln)]
    assert len(lines) == 2, r.stdout
    assert re.match(rf"#\d+ recognized {re.escape(CLI_PART)} ", lines[0]), r.stdout
    assert re.match(r"#\d+ unknown ", lines[1]), r.stdout
    rows = _rows(cell, auth)[-2:]
    want = [_bin_of(cell, auth, CLI_PART), "reject"]
    assert [r_["pick_outcome"]["bin"] for r_ in rows] == want
    assert f"placed in {want[0]}" in lines[0] and "rejected into reject" in lines[1], lines
    for line, row in zip(lines, rows, strict=True):  # the duration, as stored
        assert line.endswith(f"; {row['duration_s']:.2f} s"), (line, row["duration_s"])

    report = tmp_path / "report.csv"
    r = _cli(cell, "report", "--csv", str(report), timeout=300)
    total = len(_rows(cell, auth))
    assert re.search(rf"\binspections\b[^\n0-9]*\b{total}\b", r.stdout), r.stdout
    table = {int(t["id"]): t for t in csv.DictReader(io.StringIO(report.read_text()))}
    assert len(table) == total
    for row, b in zip(rows, want, strict=True):
        got = table[row["id"]]
        assert (got["bin"], got["pick"]) == (b, row["pick_outcome"]["outcome"]), got
        assert abs(float(got["duration_s"]) - row["duration_s"]) < 1e-3, got
