"""The browser viewer: compact packing of a recording, ``proteo view`` / ``proteo run --view``, clear
errors for bad recordings, and the written page opened in headless Chromium (modes drawn in their
colours at the first and last cycle, stepping, playing, mode toggles, cut-away, click-to-inspect,
no JavaScript error).

The browser tests need Chromium (Debian: ``apt-get install -y chromium``; ``.ci/run`` installs it);
without it they fail with that message rather than skip.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from proteo_env.core.lattice import DIRECTIONS
from proteo_env.layouts import blob_sites, place_in_box
from proteo_env.recording import Recording, load
from proteo_env.render.colours import MODE_COLOURS, OBJECT_COLOUR, SEARCH_FAR, rgb
from proteo_env.render.webview import episode_data, html_page, pack_array, unpack_array
from training.cli import main

MODES = ("SLEEP", "SEARCH", "SEED", "FINAL", "TOUCH")
SLEEP, SEARCH, SEED, FINAL, TOUCH = range(5)
N_MODULES, N_FRAMES = 60, 21


def hand_made_recording() -> Recording:
    """60 modules on the floor: SLEEP and SEED at cycle 0, SEARCH, FINAL, TOUCH and SEED at the last
    cycle; a few modules step to a neighbour site every cycle; an object beside them."""
    rng = np.random.default_rng(5)
    sites, box = place_in_box(blob_sites(N_MODULES, rng, flat=True), margin=3, floor=True)
    positions = np.repeat(sites[None].astype(np.int32), N_FRAMES, axis=0)
    flat = DIRECTIONS[DIRECTIONS[:, 2] == 0].astype(np.int32)
    for t in range(1, N_FRAMES):
        positions[t] = positions[t - 1]
        positions[t, rng.choice(N_MODULES, 3, replace=False)] += flat[rng.integers(0, len(flat), 3)]
    modes = np.full((N_FRAMES, N_MODULES), SLEEP, dtype=np.int32)
    modes[:, :5] = SEED
    final = np.array([SEARCH] * 20 + [FINAL] * 20 + [TOUCH] * 15)
    for t in range(1, N_FRAMES):
        modes[t, 5:] = np.where(np.arange(55) < 55 * t // (N_FRAMES - 1), final, SLEEP)
    scents = np.full((N_FRAMES, 1, N_MODULES), 65535, dtype=np.int32)
    scents[1:, 0, 5:25] = rng.integers(0, 6, (N_FRAMES - 1, 20))
    obj = sites[np.argmax(sites[:, 0])] + np.array([[3, 1, 0], [3, -1, 0], [4, 0, 0], [4, 0, 2]])
    return Recording(
        task_id="grasp-v0",
        overrides={},
        config={},
        seed=5,
        policy="hand-made",
        success=True,
        package_version="0.1.0",
        mode_names=MODES,
        n_agents=N_MODULES,
        box=tuple(int(b) + 6 for b in box),
        floor=True,
        scent_max=65535,
        cycles=np.arange(N_FRAMES, dtype=np.int64),
        positions=positions,
        modes=modes,
        scents=scents,
        anchored=np.zeros(N_MODULES, dtype=bool),
        solid_sites=np.zeros((0, 3), dtype=np.int64),
        object_sites=obj.astype(np.int64),
        series={"coverage": np.linspace(0, 1, N_FRAMES), "reward": np.r_[np.nan, np.ones(N_FRAMES - 1)]},
    )


@pytest.fixture(scope="module")
def recording() -> Recording:
    return hand_made_recording()


@pytest.fixture(scope="module")
def saved(recording, tmp_path_factory):
    return recording.save(tmp_path_factory.mktemp("view") / "episode.npz")


# ---------------------------------------------------------------------- packing (no browser)
def test_packed_arrays_round_trip_in_the_smallest_type(recording):
    data = episode_data(recording)
    np.testing.assert_array_equal(unpack_array(data["positions"]), recording.positions)
    np.testing.assert_array_equal(unpack_array(data["modes"]), recording.modes)
    scents = unpack_array(data["scents"])
    np.testing.assert_array_equal(scents, np.where(recording.scents == recording.scent_max, -1, recording.scents))
    np.testing.assert_array_equal(unpack_array(data["object_sites"]), recording.object_sites)
    assert data["positions"]["dtype"] == "int8" and data["scents"]["dtype"] == "int8"  # small steps, small types
    assert data["series"]["reward"][0] is None and data["series"]["coverage"][-1] == 1.0
    big = np.arange(-40000, 40000, 7, dtype=np.int64).reshape(1, -1)
    assert pack_array(big, along_time=False)["dtype"] == "int32"
    np.testing.assert_array_equal(unpack_array(pack_array(big, along_time=False)), big)


def test_a_long_episode_stays_small():
    """2,000 modules, 1,000 cycles, a few modules moving and every scent changing a little each cycle."""
    rng = np.random.default_rng(0)
    n, t = 2000, 1000
    steps = np.zeros((t, n, 3), dtype=np.int32)
    movers = rng.integers(0, n, (t, 20))
    steps[np.arange(t)[:, None], movers] = DIRECTIONS[rng.integers(0, 12, (t, 20))]
    positions = np.cumsum(steps, axis=0) + rng.integers(0, 60, (1, n, 3)) * 2
    modes = np.cumsum(rng.random((t, n)) < 0.002, axis=0) % 4
    scents = np.clip(np.cumsum(rng.integers(-1, 2, (t, 1, n)), axis=0) + 10, 0, 30)
    packed = sum(len(pack_array(a, along_time=True)["zlib_base64"]) for a in (positions, modes, scents))
    assert packed < 4e6, packed


def test_the_page_is_self_contained(recording):
    page = html_page(recording)
    assert page.count("<script") == 3 and "three.js 0.187.0" in page
    for reference in ("src=", "href=", "http://", "https://cdn", "import("):
        assert reference not in page.replace("http://www.w3.org", ""), reference


# ---------------------------------------------------------------------- command line
def test_view_writes_the_page(saved, tmp_path, capsys):
    out = tmp_path / "page.html"
    assert main(["view", str(saved), "--out", str(out)]) == 0
    assert out.is_file() and "viewer page" in capsys.readouterr().out
    assert 'id="proteo-data"' in out.read_text()


def _bad_files(saved, tmp_path):
    data = saved.read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(data[: len(data) // 2])
    corrupted = tmp_path / "corrupted.npz"
    with zipfile.ZipFile(saved) as src, zipfile.ZipFile(corrupted, "w") as dst:
        for item in src.infolist():
            raw = bytearray(src.read(item.filename))
            if item.filename == "positions.npy":
                raw[-3] ^= 0xFF
            dst.writestr(item, bytes(raw))
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    return {"truncated": truncated, "corrupted": corrupted, "other": other}


@pytest.mark.parametrize("kind", ["truncated", "corrupted", "other"])
def test_a_bad_recording_gets_the_recordings_error_and_no_page(saved, tmp_path, capsys, kind):
    path = _bad_files(saved, tmp_path)[kind]
    out = tmp_path / "page.html"
    with pytest.raises(Exception) as expected:
        load(path)
    assert main(["view", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(expected.value) in err and "allowed" in err
    assert not out.exists()


def test_view_refuses_a_page_name_without_html(saved, tmp_path, capsys):
    assert main(["view", str(saved), "--out", str(tmp_path / "page.png")]) == 2
    assert "allowed: a file name ending in .html" in capsys.readouterr().err


def test_run_writes_the_page(tmp_path):
    out = tmp_path / "run.html"
    assert main(["run", "chain-v0", "--set", "n_modules=6", "--set", "max_cycles=3", "--view", str(out)]) == 0
    assert 'id="proteo-data"' in out.read_text()


# ---------------------------------------------------------------------- in the browser
@pytest.fixture(scope="module")
def browser():
    from proteo_env.render.browser import BrowserError, Chromium, find_chromium

    try:
        find_chromium()
    except BrowserError as err:
        pytest.fail(f"the browser tests need Chromium: {err}")
    with Chromium(width=1100, height=760) as chromium:
        yield chromium


@pytest.fixture(scope="module")
def page(recording, tmp_path_factory):
    from proteo_env.render.webview import write_html

    return write_html(recording, tmp_path_factory.mktemp("page") / "episode.html")


def settle(browser) -> None:
    """Wait until the page has drawn two more pictures after the last change."""
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", await_promise=True)
    browser.evaluate("proteoViewer.render()")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", await_promise=True)


def colour_pixels(browser) -> dict[str, int]:
    """Pixels of the 3D view whose colour is a shade of each mode's colour (and the object's)."""
    from PIL import Image

    settle(browser)
    rect = browser.evaluate(
        "(() => { const r = document.getElementById('view').getBoundingClientRect(); "
        "return [r.left, r.top, r.right, r.bottom].map(Math.round); })()"
    )
    image = np.asarray(Image.open(io.BytesIO(browser.screenshot())).convert("RGB"), dtype=float) / 255
    pixels = image[rect[1] : rect[3], rect[0] : rect[2]].reshape(-1, 3)
    bright = pixels[np.linalg.norm(pixels, axis=1) > 0.15]
    direction = bright / np.linalg.norm(bright, axis=1, keepdims=True)
    shades = {
        "SEARCH": (MODE_COLOURS["SEARCH"], SEARCH_FAR),
        "SEED": (MODE_COLOURS["SEED"],),
        "TOUCH": (MODE_COLOURS["TOUCH"],),
        "object": (OBJECT_COLOUR,),
    }
    counts = {}
    for name, colours in shades.items():
        match = np.zeros(len(direction), dtype=bool)
        for colour in colours:  # a lit face is the colour times a shade: same direction in RGB
            base = rgb(colour) / np.linalg.norm(rgb(colour))
            match |= direction @ base > 0.998
        counts[name] = int(match.sum())
    return counts


@pytest.mark.slow  # the browser
def test_the_first_and_last_cycles_are_drawn_in_mode_colours(browser, page, recording):
    browser.open(page)
    assert browser.evaluate("document.body.dataset.frame") == "0"
    assert browser.evaluate("document.body.dataset.modules") == str(N_MODULES)
    assert browser.evaluate("document.title") == f"proteo · grasp-v0 · cycle 0 / {N_FRAMES - 1} · {N_MODULES} modules"
    first = colour_pixels(browser)
    assert first["SEED"] > 50 and first["object"] > 50, first
    assert first["SEARCH"] < 5 and first["TOUCH"] < 5, first  # no module is in these modes at cycle 0

    browser.evaluate("location.hash = '#frame=-1'")
    browser.wait_for(f"document.body.dataset.cycle === '{N_FRAMES - 1}'")
    assert browser.evaluate("document.title").startswith(f"proteo · grasp-v0 · cycle {N_FRAMES - 1} /")
    last = colour_pixels(browser)
    assert last["SEARCH"] > 50 and last["TOUCH"] > 50 and last["SEED"] > 20, last
    counts = browser.evaluate("proteoViewer.state().modeCounts")
    assert counts == np.bincount(recording.modes[-1], minlength=len(MODES)).tolist()
    assert browser.errors() == [] and browser.evaluate("document.body.dataset.errors") == "0"


@pytest.mark.slow  # the browser
def test_positions_follow_the_recording_when_stepping_and_seeking(browser, page, recording):
    browser.open(str(page.resolve().as_uri()) + "#cycle=7")
    inspected = 0
    for action, frame in (("forward", 8), ("back", 7), ("back", 6), ("last", N_FRAMES - 1), ("first", 0)):
        browser.evaluate(f"document.getElementById('{action}').click()")
        assert browser.evaluate("document.body.dataset.frame") == str(frame)
        for module in (0, 17, 42):
            browser.evaluate(f"proteoViewer.pick(...proteoViewer.project({module}))")
            picked = int(browser.evaluate("document.body.dataset.picked"))
            if picked < 0:
                continue  # hidden behind another module's edge; the next one is checked
            row = browser.evaluate(
                "Object.fromEntries([...document.querySelectorAll('#picked tr')]"
                ".map(r => [r.dataset.key, r.cells[1].textContent]))"
            )
            assert row["mode"] == MODES[recording.modes[frame, picked]]
            assert row["site"] == ", ".join(map(str, recording.positions[frame, picked]))
            scent = recording.scents[frame, 0, picked]
            assert row["scents"] == ("none" if scent == recording.scent_max else str(scent))
            inspected += 1
    assert inspected >= 10 and browser.errors() == []


@pytest.mark.slow  # the browser
def test_play_toggles_and_cut_away(browser, page):
    browser.open(page)
    browser.evaluate("document.getElementById('speed').value = '20'")
    browser.evaluate("document.getElementById('play').click()")
    browser.wait_for("Number(document.body.dataset.frame) > 2", timeout=10)
    browser.evaluate("document.getElementById('play').click()")
    assert browser.evaluate("proteoViewer.state().playing") is False

    browser.evaluate("location.hash = '#frame=-1'")
    browser.wait_for(f"document.body.dataset.frame === '{N_FRAMES - 1}'")
    assert colour_pixels(browser)["TOUCH"] > 50
    browser.evaluate(f"document.querySelectorAll('#modes input')[{TOUCH}].click()")
    assert int(browser.evaluate("document.body.dataset.drawn")) == N_MODULES - 15
    assert colour_pixels(browser)["TOUCH"] < 5
    browser.evaluate(f"document.querySelectorAll('#modes input')[{TOUCH}].click()")

    whole = colour_pixels(browser)
    browser.evaluate(
        "(() => { const a = document.getElementById('cut-axis'); a.value = '0'; "
        "a.dispatchEvent(new Event('change')); const c = document.getElementById('cut-at'); "
        "c.value = c.min; c.dispatchEvent(new Event('input')); })()"
    )
    cut = colour_pixels(browser)
    assert sum(cut.values()) < sum(whole.values()) / 4, (cut, whole)  # the plane hides almost everything
    assert browser.errors() == [] and browser.evaluate("document.body.dataset.errors") == "0"
