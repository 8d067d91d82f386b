"""Recorded episodes: exact round trip, reproduction from the header, clear errors for bad files,
plots of the recorded series, and the ``proteo run`` / ``proteo replay`` commands."""

from __future__ import annotations

import json
import zipfile

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import proteo_env  # noqa: E402
from baselines import make_policy  # noqa: E402
from proteo_env.recording import FORMAT_VERSION, Recorder, Recording, RecordingError, load  # noqa: E402
from proteo_env.rollout import run_episode  # noqa: E402

OVERRIDES = {"n_modules": 10, "max_cycles": 25}


def record(seed: int = 3) -> Recording:
    env = proteo_env.make("chain-v0", **OVERRIDES)
    policy = make_policy("chain", env, seed=seed)
    recorder = Recorder(env, task_id="chain-v0", overrides=OVERRIDES, seed=seed, policy=policy.name)
    result = run_episode(env, policy, seed=seed, observe=recorder)
    rec = recorder.recording(success=result.success)
    assert rec.n_frames == result.cycles + 1
    np.testing.assert_array_equal(rec.positions[-1], env.world.positions)
    np.testing.assert_array_equal(rec.modes[-1], env.world.modes)
    np.testing.assert_array_equal(rec.scents[-1], env.world.scents)
    return rec


@pytest.fixture(scope="module")
def recording() -> Recording:
    return record()


@pytest.fixture(scope="module")
def saved(recording, tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "episode.npz"
    recording.save(path)
    return path


# ---------------------------------------------------------------------- round trip
def test_round_trip_is_exact(recording, saved):
    loaded = load(saved)
    assert loaded.equals(recording)
    assert loaded.task_id == "chain-v0" and loaded.seed == 3 and loaded.policy == "chain"
    assert loaded.package_version == proteo_env.__version__
    assert loaded.overrides == OVERRIDES
    assert loaded.config["max_cycles"] == 25 and loaded.config["task"]["n_modules"] == 10
    assert loaded.config["physics"]["motion_model"] == proteo_env.Physics().motion_model
    assert loaded.cycles.tolist() == list(range(recording.n_frames))
    assert np.isnan(loaded.series["reward"][0]) and "chain_length" in loaded.series
    assert saved.stat().st_size < 20_000, "compact: differences along time, compressed"


def test_the_header_reproduces_the_episode(recording):
    """Same task, overrides, seed and policy: the same frames, bit for bit."""
    again = record(recording.seed)
    for name in ("positions", "modes", "scents", "cycles"):
        np.testing.assert_array_equal(getattr(again, name), getattr(recording, name))


# ---------------------------------------------------------------------- bad files
def _rewrite(src, dst, *, header=None, **arrays):
    """Copy a recording's stored members, replacing the header fields and members given."""
    with np.load(src) as f:
        members = {k: f[k] for k in f.files}
    h = json.loads(members["header"].tobytes().decode())
    h.update(header or {})
    members["header"] = np.frombuffer(json.dumps(h).encode(), dtype=np.uint8)
    members.update(arrays)
    np.savez_compressed(dst, **members)
    return dst


def _flip_in_member(src, dst, member: str):
    """Copy ``src`` with one byte flipped in the middle of a member's compressed data."""
    data = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as z:
        info = z.getinfo(member + ".npy")
    name_len = int.from_bytes(data[info.header_offset + 26 : info.header_offset + 28], "little")
    extra_len = int.from_bytes(data[info.header_offset + 28 : info.header_offset + 30], "little")
    start = info.header_offset + 30 + name_len + extra_len
    data[start + info.compress_size // 2] ^= 0xFF
    dst.write_bytes(bytes(data))
    return dst


def _assert_clear(path, *words):
    with pytest.raises(RecordingError) as err:
        load(path)
    message = str(err.value)
    assert str(path) in message and "allowed" in message, message
    for w in words:
        assert w in message, message
    return message


@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, 0.999])
def test_truncated_file(saved, tmp_path, keep):
    data = saved.read_bytes()
    path = tmp_path / "cut.npz"
    path.write_bytes(data[: int(len(data) * keep)])
    _assert_clear(path, "truncated or corrupted")


@pytest.mark.parametrize("member", ["header", "positions", "scents", "series"])
def test_corrupted_file(saved, tmp_path, member):
    _assert_clear(_flip_in_member(saved, tmp_path / "bad.npz", member))


def test_wrong_format_version(saved, tmp_path):
    message = _assert_clear(_rewrite(saved, tmp_path / "v.npz", header={"format_version": 99}), "format_version 99")
    assert f"allowed: format_version {FORMAT_VERSION}" in message


def test_not_a_recording(tmp_path):
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    _assert_clear(tmp_path / "other.npz", "not a proteo recording")
    np.save(tmp_path / "bare.npy", np.zeros(3))
    _assert_clear(tmp_path / "bare.npy", "not a proteo recording")
    (tmp_path / "text.npz").write_text("hello")
    _assert_clear(tmp_path / "text.npz", "truncated or corrupted")
    _assert_clear(tmp_path / "missing.npz", "no such file")
    _assert_clear(_header_only(tmp_path / "fmt.npz", {"format": "something-else"}), "not a proteo recording")


def _header_only(path, header):
    np.savez(path, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    return path


def test_mismatched_arrays(saved, tmp_path):
    other = record(seed=5)
    other_path = other.save(tmp_path / "other.npz")
    with np.load(other_path) as f:
        other_positions = f["positions"]
    with np.load(saved) as f:
        own_positions = f["positions"]
    if other_positions.shape == own_positions.shape:  # same length: the checksum catches it
        _assert_clear(_rewrite(saved, tmp_path / "mixed.npz", positions=other_positions), "'positions'", "checksum")
    else:
        _assert_clear(_rewrite(saved, tmp_path / "mixed.npz", positions=other_positions), "'positions'", "header")
    _assert_clear(_rewrite(saved, tmp_path / "short.npz", positions=own_positions[:-1]), "'positions'", "shape")
    with np.load(saved) as f:
        members = {k: f[k] for k in f.files if k != "modes"}
    np.savez_compressed(tmp_path / "missing.npz", **members)
    _assert_clear(tmp_path / "missing.npz", "'modes'", "missing")


# ---------------------------------------------------------------------- plots
def test_plot_groups_and_weight_shifts(recording, monkeypatch, tmp_path):
    from proteo_env.render.plots import plot_groups, plot_recording, weight_shifts
    from proteo_env.tasks.chain import Chain

    groups = plot_groups(recording)
    assert groups["chain length"] == ["chain_length"] and groups["connected pieces"] == ["components"]
    monkeypatch.setattr(Chain, "plot_groups", {"shape": ["chain_length", "max_degree", "not_a_metric"]})
    groups = plot_groups(recording)
    assert groups["shape"] == ["chain_length", "max_degree"] and "max degree" not in groups

    t = recording.n_frames
    weight = np.where(np.arange(t) < t // 2, 7.0, 3.0)
    series = {"legs_region_0": np.arange(t, dtype=float), "legs_region_1": np.ones(t), "weight_left": weight}
    table_like = Recording(**{**recording.__dict__, "task_id": "unregistered-v0", "series": series})
    assert plot_groups(table_like) == {
        "legs per region": ["legs_region_0", "legs_region_1"],
        "weight left": ["weight_left"],
    }
    assert weight_shifts(table_like) == [int(recording.cycles[t // 2])]
    paths = plot_recording(table_like, tmp_path / "plots")
    assert [p.name for p in paths] == ["overview.png", "legs_per_region.png", "weight_left.png"]
    assert all(p.stat().st_size > 1000 for p in paths)


# ---------------------------------------------------------------------- command line
def test_run_record_render_and_replay(tmp_path, capsys):
    from training.cli import main

    ep, movie, plots = tmp_path / "ep.npz", tmp_path / "movie.gif", tmp_path / "plots"
    assert (
        main(
            [
                "run",
                "chain-v0",
                "--set",
                "n_modules=8",
                "--set",
                "max_cycles=12",
                "--policy",
                "chain",
                "--record",
                str(ep),
                "--render",
                str(movie),
                "--plots",
                str(plots),
                "--size",
                "160x120",
                "--max-frames",
                "4",
            ]
        )
        == 0
    )
    rec = load(ep)
    assert rec.overrides == {"n_modules": 8, "max_cycles": 12} and rec.positions.shape[1] == 8
    assert movie.is_file() and (plots / "overview.png").is_file()
    still = tmp_path / "still.png"
    assert main(["replay", str(ep), "--out", str(still), "--cycle", "5", "--size", "120x90"]) == 0
    from PIL import Image

    with Image.open(still) as im:
        assert im.size == (120, 90)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(ep.read_bytes()[:100])
    assert main(["replay", str(bad), "--out", str(tmp_path / "x.gif")]) == 2
    assert "truncated or corrupted" in capsys.readouterr().err
    assert main(["run", "chain-v0", "--record", str(tmp_path / "ep.txt")]) == 2
    assert "allowed: a file name ending in .npz" in capsys.readouterr().err
    assert main(["run", "no-such-task"]) == 2
    err = capsys.readouterr().err
    assert "unknown task 'no-such-task'" in err and "chain-v0" in err
