"""Recorded episodes: every cycle's positions, modes and scents, in one compact ``.npz`` file.

A recording holds frame 0 (after ``reset``) and one frame after every cycle, plus what is
needed to know where it came from: the task id, the overrides it was built with and the
resolved config, the seed, the policy and the package version. It also keeps the per-frame
series that plots are drawn from: the task's metrics (``metric/<name>`` in ``infos``), the
team reward, the number of modules that moved and the number of connected pieces.

File layout (``numpy.savez_compressed``, no pickled objects):

================ ==================== =====================================================
member           shape                content
================ ==================== =====================================================
``header``       (bytes,) uint8       UTF-8 JSON: format, format_version, package_version,
                                      task_id, overrides, config, seed, policy, success,
                                      mode_names, box, floor, scent_max, n_agents,
                                      series_names, and per array its shape, dtype, crc32
``cycles``       (T,) int64           cycle of each frame (0, 1, ...)
``positions``    (T, N, 3) int16/32   module sites, stored as differences along time
``modes``        (T, N) int8/16/32    modes, stored as differences along time
``scents``       (T, C, N) uint16/i32 scents, stored as differences along time
``anchored``     (N,) bool            modules that never move
``solid_sites``  (S, 3) int64         obstacle sites
``object_sites`` (O, 3) int64         object sites
``series``       (T, K) float64       ``series_names[k]`` per frame (NaN where undefined)
================ ==================== =====================================================

:func:`load` checks everything it reads: a missing, truncated or corrupted file, a file that
is not a recording, an unsupported ``format_version``, or arrays that do not match the
header or their checksums raise :class:`RecordingError` with one message that names what is
wrong and what is allowed.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

FORMAT = "proteo-recording"
FORMAT_VERSION = 1
"""Version of the file layout; files of another version are refused."""

DELTA_ARRAYS = ("positions", "modes", "scents")
ARRAYS = ("cycles", "positions", "modes", "scents", "anchored", "solid_sites", "object_sites", "series")
ALLOWED = "allowed: a complete .npz file written by `proteo run --record` (format_version 1)"


class RecordingError(ValueError):
    """A recording file that cannot be loaded (the message says what is wrong and what is allowed)."""


def _package_version() -> str:
    from . import __version__

    return __version__


@dataclasses.dataclass
class Recording:
    """One recorded episode (``T`` frames: after reset and after each cycle).

    Attributes:
        task_id: registered task id.
        overrides: the overrides given to :func:`proteo_env.make` (rebuilds the env).
        config: the resolved settings (env, physics, task parameters), for the record.
        seed: the episode's seed; policy: the policy's name; success: the task's flag at the end.
        package_version: the proteo version that wrote the file.
        mode_names, n_agents, box, floor, scent_max: as in :class:`~proteo_env.env.WorldView`.
        cycles: ``(T,)`` int64; positions: ``(T, N, 3)``, modes: ``(T, N)``, scents: ``(T, C, N)``,
            all int32 in memory (stored smaller).
        anchored: ``(N,)``; solid_sites: ``(S, 3)``; object_sites: ``(O, 3)``.
        series: name -> ``(T,)`` float per-frame values (metrics, ``reward``, ``moved``,
            ``components``); NaN where a value is undefined (the reward of frame 0).
    """

    task_id: str
    overrides: dict
    config: dict
    seed: int
    policy: str
    success: bool
    package_version: str
    mode_names: tuple
    n_agents: int
    box: tuple
    floor: bool
    scent_max: int
    cycles: np.ndarray
    positions: np.ndarray
    modes: np.ndarray
    scents: np.ndarray
    anchored: np.ndarray
    solid_sites: np.ndarray
    object_sites: np.ndarray
    series: dict

    @property
    def n_frames(self) -> int:
        return len(self.cycles)

    def metric_names(self) -> list[str]:
        """The task's metric names (series without the built-in ones)."""
        return [k for k in self.series if k not in BUILTIN_SERIES]

    def scene(self, frame: int, caption: str | None = None):
        """The :class:`~proteo_env.render.scene.Scene` of frame ``frame`` (caption: task and cycle)."""
        from .render.scene import Scene

        if caption is None:
            caption = f"{self.task_id} · {self.policy} · cycle {int(self.cycles[frame])}"
        return Scene(
            positions=self.positions[frame],
            modes=self.modes[frame],
            mode_names=self.mode_names,
            scent=self.scents[frame, 0] if self.scents.shape[1] else None,
            scent_max=self.scent_max,
            solid_sites=self.solid_sites,
            object_sites=self.object_sites,
            box=self.box,
            floor=self.floor,
            caption=caption,
        )

    def sites_visited(self, max_frames: int = 64) -> np.ndarray:
        """``(K, 3)`` distinct module sites of up to ``max_frames`` evenly spread frames, and the object's."""
        frames = np.unique(np.linspace(0, self.n_frames - 1, min(max_frames, self.n_frames)).astype(np.int64))
        sites = np.concatenate([self.positions[frames].reshape(-1, 3), self.object_sites.astype(np.int32)])
        return np.unique(sites, axis=0)

    def scent_range(self) -> int:
        """The largest scent below ``scent_max`` on channel 0 of a SEARCH module over the episode (at least 1)."""
        if not self.scents.shape[1] or "SEARCH" not in self.mode_names:
            return 1
        s = self.scents[:, 0][self.modes == self.mode_names.index("SEARCH")]
        s = s[s < self.scent_max]
        return max(int(s.max()), 1) if s.size else 1

    def equals(self, other: Recording) -> bool:
        """True when every field and array is identical."""
        for f in dataclasses.fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray):
                if not (
                    isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
                ):
                    return False
            elif f.name == "series":
                if list(a) != list(b) or not all(np.array_equal(a[k], b[k], equal_nan=True) for k in a):
                    return False
            elif a != b:
                return False
        return True

    # ------------------------------------------------------------------ file
    def save(self, path) -> Path:
        """Write the recording to ``path`` (``.npz``; written to a temporary file, then renamed)."""
        path = Path(path)
        arrays = {
            "cycles": self.cycles.astype(np.int64),
            "positions": self.positions.astype(_int_dtype(self.positions)),
            "modes": self.modes.astype(_int_dtype(self.modes)),
            "scents": self.scents.astype(np.uint16 if self.scent_max <= 65535 else np.int32),
            "anchored": self.anchored.astype(np.bool_),
            "solid_sites": self.solid_sites.astype(np.int64).reshape(-1, 3),
            "object_sites": self.object_sites.astype(np.int64).reshape(-1, 3),
            "series": np.stack([np.asarray(v, dtype=np.float64) for v in self.series.values()], axis=1)
            if self.series
            else np.zeros((self.n_frames, 0)),
        }
        header = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "package_version": self.package_version,
            "task_id": self.task_id,
            "overrides": self.overrides,
            "config": self.config,
            "seed": self.seed,
            "policy": self.policy,
            "success": bool(self.success),
            "mode_names": list(self.mode_names),
            "n_agents": int(self.n_agents),
            "box": [int(v) for v in self.box],
            "floor": bool(self.floor),
            "scent_max": int(self.scent_max),
            "series_names": list(self.series),
            "arrays": {
                k: {"shape": list(a.shape), "dtype": a.dtype.str, "crc32": zlib.crc32(a.tobytes())}
                for k, a in arrays.items()
            },
        }
        stored = {k: _delta(a) if k in DELTA_ARRAYS else a for k, a in arrays.items()}
        stored["header"] = np.frombuffer(json.dumps(header, default=_json_default).encode(), dtype=np.uint8)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **stored)
        tmp.replace(path)
        return path


BUILTIN_SERIES = ("reward", "moved", "components")
"""Series every recording has besides the task's metrics."""


def _int_dtype(a: np.ndarray):
    """The smallest signed integer type that holds every value of ``a``."""
    lo, hi = (int(a.min()), int(a.max())) if a.size else (0, 0)
    for dtype in (np.int8, np.int16, np.int32):
        info = np.iinfo(dtype)
        if info.min <= lo and hi <= info.max:
            return dtype
    return np.int64


def _delta(a: np.ndarray) -> np.ndarray:
    """Differences along the first axis (first row kept); integer wrap-around is undone by cumsum."""
    return np.diff(a, axis=0, prepend=np.zeros((1,) + a.shape[1:], dtype=a.dtype)) if len(a) else a


def _json_default(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, (np.ndarray, tuple, set)):
        return list(value)
    return str(value)


# ---------------------------------------------------------------------- loading
def load(path) -> Recording:
    """Read a recording written by :meth:`Recording.save`, checking it completely.

    Raises:
        RecordingError: the file is missing, truncated or corrupted, is not a recording, has
            an unsupported ``format_version``, or its arrays do not match its header.
    """
    path = Path(path)
    where = f"recording {str(path)!r}"
    if not path.is_file():
        raise RecordingError(f"{where}: no such file; {ALLOWED}")
    try:
        archive = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, zlib.error) as err:
        raise RecordingError(
            f"{where} is truncated or corrupted: not a readable .npz archive ({err}); {ALLOWED}"
        ) from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise RecordingError(f"{where} is not a proteo recording (a bare .npy array, not an .npz archive); {ALLOWED}")
    with archive:
        if "header" not in archive.files:
            raise RecordingError(
                f"{where} is not a proteo recording (no 'header' member; found: "
                f"{', '.join(archive.files) or 'nothing'}); {ALLOWED}"
            )
        header = _read_header(archive, where)
        arrays = {name: _read_array(archive, name, header, where) for name in ARRAYS}
    return _assemble(header, arrays, where)


def _member(archive, name: str, where: str) -> np.ndarray:
    try:
        return archive[name]
    except KeyError:
        raise RecordingError(
            f"{where} is not a complete recording: member {name!r} is missing "
            f"(found: {', '.join(archive.files)}); {ALLOWED}"
        ) from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, zlib.error) as err:
        raise RecordingError(
            f"{where} is truncated or corrupted: member {name!r} cannot be read ({err}); {ALLOWED}"
        ) from None


def _read_header(archive, where: str) -> dict:
    raw = _member(archive, "header", where)
    try:
        header = json.loads(raw.astype(np.uint8).tobytes().decode())
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError) as err:
        raise RecordingError(f"{where}: the header is not valid JSON ({err}); {ALLOWED}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise RecordingError(f"{where} is not a proteo recording (format {found!r}); allowed: format {FORMAT!r}")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise RecordingError(
            f"{where}: format_version {version!r} (written by proteo "
            f"{header.get('package_version', '?')}) is not supported; allowed: format_version "
            f"{FORMAT_VERSION} (this is proteo {_package_version()})"
        )
    required = (
        "package_version",
        "task_id",
        "overrides",
        "config",
        "seed",
        "policy",
        "success",
        "mode_names",
        "n_agents",
        "box",
        "floor",
        "scent_max",
        "series_names",
        "arrays",
    )
    missing = [k for k in required if k not in header]
    if missing:
        raise RecordingError(
            f"{where}: header field {missing[0]!r} is missing; allowed: a header with {', '.join(required)}"
        )
    missing = [k for k in ARRAYS if k not in header["arrays"]]
    if missing:
        raise RecordingError(
            f"{where}: header describes no array {missing[0]!r}; allowed: a header describing {', '.join(ARRAYS)}"
        )
    return header


def _read_array(archive, name: str, header: dict, where: str) -> np.ndarray:
    spec = header["arrays"][name]
    stored = _member(archive, name, where)
    if list(stored.shape) != list(spec["shape"]) or stored.dtype.str != spec["dtype"]:
        raise RecordingError(
            f"{where}: array {name!r} has shape {tuple(stored.shape)} and dtype {stored.dtype.str}, "
            f"but the header says shape {tuple(spec['shape'])} and dtype {spec['dtype']}; "
            "allowed: arrays that match the header (the file was altered or mixed with another)"
        )
    a = np.cumsum(stored, axis=0, dtype=stored.dtype) if name in DELTA_ARRAYS and len(stored) else stored
    if zlib.crc32(a.tobytes()) != spec["crc32"]:
        raise RecordingError(f"{where}: array {name!r} does not match its checksum (corrupted or altered); {ALLOWED}")
    return a


def _assemble(header: dict, a: dict, where: str) -> Recording:
    t = len(a["cycles"])
    n = a["anchored"].shape[0] if a["anchored"].ndim == 1 else -1
    names = header["series_names"]
    expected = {"positions": (t, n, 3), "modes": (t, n), "series": (t, len(names))}
    for name, shape in expected.items():
        if a[name].shape != shape:
            raise RecordingError(
                f"{where}: array {name!r} has shape {a[name].shape}; allowed: {shape} "
                f"({t} frames, {n} modules, {len(names)} series)"
            )
    if a["scents"].ndim != 3 or a["scents"].shape[0] != t or a["scents"].shape[2] != n:
        raise RecordingError(f"{where}: array 'scents' has shape {a['scents'].shape}; allowed: ({t}, C, {n})")
    mode_names = tuple(header["mode_names"])
    if a["modes"].size and not (0 <= a["modes"].min() and a["modes"].max() < len(mode_names)):
        raise RecordingError(
            f"{where}: modes outside 0..{len(mode_names) - 1}; allowed: indices of mode_names {list(mode_names)}"
        )
    return Recording(
        task_id=str(header["task_id"]),
        overrides=dict(header["overrides"]),
        config=dict(header["config"]),
        seed=header["seed"],
        policy=str(header["policy"]),
        success=bool(header["success"]),
        package_version=str(header["package_version"]),
        mode_names=mode_names,
        n_agents=int(header["n_agents"]),
        box=tuple(header["box"]),
        floor=bool(header["floor"]),
        scent_max=int(header["scent_max"]),
        cycles=a["cycles"],
        positions=a["positions"].astype(np.int32),
        modes=a["modes"].astype(np.int32),
        scents=a["scents"].astype(np.int32),
        anchored=a["anchored"],
        solid_sites=a["solid_sites"],
        object_sites=a["object_sites"],
        series={k: a["series"][:, i] for i, k in enumerate(names)},
    )


# ---------------------------------------------------------------------- recording
class Recorder:
    """Collects the frames of one episode; pass it as ``observe`` to :func:`~proteo_env.rollout.run_episode`.

    Args:
        env: the environment being run.
        task_id, overrides: how the environment was built (``proteo_env.make(task_id, **overrides)``).
        seed: the episode's seed.
        policy: the policy's name.
    """

    def __init__(self, env, *, task_id: str, overrides: dict, seed: int | None, policy: str):
        self.env = env
        self.task_id, self.seed, self.policy = task_id, seed, policy
        self.overrides = json.loads(json.dumps(dict(overrides), default=_json_default))  # as the file keeps them
        self._frames: list[tuple] = []
        self._series: list[dict] = []

    def __call__(self, env, info: dict) -> None:
        """Capture the current world as the next frame (call after reset and after each cycle)."""
        if info.get("cycle", 0) == 0:
            self._frames.clear()
            self._series.clear()
        e = env.engine
        self._frames.append(
            (env.cycle, e.positions.astype(np.int32), e.mode.astype(np.int32), e.scent.astype(np.int32))
        )
        row = {k.removeprefix("metric/"): float(v) for k, v in info.items() if k.startswith("metric/")}
        rewards = [v for k, v in info.items() if k.startswith("reward/")]
        row["reward"] = float(sum(rewards)) if env.cycle > 0 else float("nan")
        row["moved"] = float(info.get("moved", 0)) if env.cycle > 0 else float("nan")
        row["components"] = float(e.n_components())
        self._series.append(row)

    def recording(self, *, success: bool) -> Recording:
        """The episode captured so far as a :class:`Recording`."""
        if not self._frames:
            raise RuntimeError("nothing recorded yet; run an episode with this recorder as `observe`")
        env, e = self.env, self.env.engine
        names = list(dict.fromkeys(k for row in self._series for k in row if k not in BUILTIN_SERIES))
        names += list(BUILTIN_SERIES)
        series = {k: np.array([row.get(k, np.nan) for row in self._series], dtype=np.float64) for k in names}
        return Recording(
            task_id=self.task_id,
            overrides=self.overrides,
            config=_resolved_config(env),
            seed=self.seed,
            policy=self.policy,
            success=bool(success),
            package_version=_package_version(),
            mode_names=tuple(env.task.modes),
            n_agents=e.n_agents,
            box=tuple(int(v) for v in e.shape.size),
            floor=bool(e.floor),
            scent_max=int(e.physics.scent_max),
            cycles=np.array([f[0] for f in self._frames], dtype=np.int64),
            positions=np.stack([f[1] for f in self._frames]),
            modes=np.stack([f[2] for f in self._frames]),
            scents=np.stack([f[3] for f in self._frames]),
            anchored=e.anchored.copy(),
            solid_sites=np.asarray(e.solid_sites, dtype=np.int64).reshape(-1, 3),
            object_sites=np.asarray(e.object_sites, dtype=np.int64).reshape(-1, 3),
            series=series,
        )


def _resolved_config(env) -> dict:
    """Every setting in force: env config, physics and task parameters, JSON-ready."""
    config = dataclasses.asdict(env.config)
    params = env.task.params
    config["task"] = dataclasses.asdict(params) if dataclasses.is_dataclass(params) else {}
    return json.loads(json.dumps(config, default=_json_default))
