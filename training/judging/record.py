"""The one file format of a judgement: ``results.json`` and ``benchmark.json``, and their tables.

``proteo eval`` writes ``OUT/results.json`` and ``OUT/results.md``; ``proteo eval --benchmark``
writes ``OUT/benchmark.json`` and ``OUT/benchmark.md``. Both are one document, schema
:data:`SCHEMA` version :data:`SCHEMA_VERSION`, written by :func:`document` (whose fields, as
written there, are the schema; docs/guides/benchmark.md describes them) and one table writer,
:func:`markdown`. Its ``judgement`` says which command wrote it: ``evaluation`` (the settings
come from an eval config; ``protocol`` and its fields are null) or ``benchmark`` (a versioned
protocol fixes them). A row is one :class:`~training.judging.report.Result`: a policy, or one
recipe's training seeds, on one task and split, with every episode of every run.

:func:`load` reads any version back as the current one: a ``benchmark.json`` of schema
``proteo-benchmark-results`` version 1 (the v1 to v7 judgements as published) gains ``judgement``,
``deterministic`` and each row's ``group``; a ``results.json`` written before this format (no
``schema``: a row per run, its group's label beside it) is gathered into rows. :func:`rerender`
(``proteo eval --from-results FILE``) writes a file's tables again, in the current format, without
playing an episode.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

from proteo_env.config import ConfigError
from proteo_env.registry import task_name
from training.judging.pages import filled
from training.judging.protocol import PROTOCOL_DIR
from training.judging.report import (
    BENCHMARK_COLUMNS,
    EVALUATION_COLUMNS,
    INTERVALS,
    PUBLISH_END,
    Result,
    Run,
    markdown_table,
    page_tables,
    plot,
)
from training.machinery.checkpoints import provenance

SCHEMA = "proteo-results"
SCHEMA_VERSION = 2
FILE_NAMES = {"evaluation": "results", "benchmark": "benchmark"}
"""The name (``.json``, ``.md``) a document is written under, by its ``judgement``."""
V1_SCHEMA = "proteo-benchmark-results"
"""The schema of ``benchmark.json`` before version 2 (:func:`load` reads it)."""


def document(
    results: list[Result],
    *,
    judgement: str,
    seconds: float,
    protocol=None,
    deterministic: bool = False,
    worlds_cap: int | None = None,
    notes=(),
) -> dict:
    """The document of the judged ``results`` (one :class:`Result` per row, every episode played):
    ``judgement`` ``"evaluation"`` (``proteo eval``) or ``"benchmark"`` (``protocol``, a
    :class:`~training.judging.protocol.Protocol`, judged by); ``notes``: why a row is not complete.

    A row's ``summary`` is :meth:`Result.summary`: ``episodes``, ``successes``, ``success_rate``,
    ``success_lo``/``success_hi`` (the 95 % interval), ``cycles_to_success`` with
    ``cycles_lo``/``cycles_hi`` (over the successful episodes), ``return_mean`` with
    ``return_lo``/``return_hi``, ``training_seeds`` and ``interval`` (one run: Wilson and Student t;
    several training seeds: the stratified bootstrap of
    :func:`training.judging.statistics.group_bootstrap`). The fields, as written below, are the
    schema."""
    if judgement not in FILE_NAMES:
        raise ValueError(f"judgement {judgement!r}: one of {', '.join(FILE_NAMES)}")
    rows = [
        {
            "task": r.task,
            "task_name": task_name(r.task),
            "split": r.split,  # the protocol's split ("" in an evaluation)
            "about": r.about,
            "env": r.env,  # the proteo_env.make settings (an evaluation: its config's settings for the task)
            "policy": r.policy,  # rules, rules-move, random, a checkpoint's algorithm, a group's, recipe's or entrant's label
            "kind": r.kind,  # hand-coded, random, learned, evolved
            "level": r.level,
            "group": r.group,  # the runs are one configuration's training seeds (summarised together)
            "recipe": r.recipe,  # the protocol recipe its checkpoints ran, or None
            # reference (rules, random), protocol (a recipe's checkpoints, checked), declared (an
            # entrant.yaml), undeclared (a bare factory), unchecked (checkpoints of no recipe); None in an
            # evaluation
            "training": r.training,
            "declared": r.declared,  # an entrant's {name, training_seeds, budget, code}
            "world_seeds": r.world_seeds,  # the worlds every run played, in order
            "complete": r.complete,  # judged on every world and training seed its protocol asks for
            "runs": [  # one per training seed (one for the rules, random and a lone checkpoint)
                {
                    "source": run.source,  # the checkpoint, the entrant's file, or baselines.<policy>
                    "training_seed": run.training_seed,
                    "agent_steps": run.agent_steps,  # None for the rules and random
                    **({"sha256": run.sha256} if run.sha256 else {}),  # an entrant's file
                    "successes": [bool(s) for s in run.successes],
                    "cycles": [int(c) for c in run.cycles],
                    "returns": [float(x) for x in run.returns],
                    # the task's metrics at each episode's end (an evaluation; a benchmark leaves them out)
                    **({"metrics": run.metrics} if judgement == "evaluation" else {}),
                    "seconds": run.seconds,
                }
                for run in r.runs
            ],
            "summary": r.summary(),
        }
        for r in results
    ]
    return {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "judgement": judgement,
        "protocol": protocol.version if protocol else None,
        "protocol_file": f"{PROTOCOL_DIR}/{protocol.version}.yaml" if protocol else None,
        "protocol_sha256": protocol.sha256 if protocol else None,  # the protocol file judged by
        **provenance(),  # proteo_version, commit
        "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "deterministic": deterministic,  # learned neural policies took arg-max actions
        "worlds_cap": worlds_cap,  # --worlds-cap (quick checks only; a published run has None)
        "complete": all(r["complete"] for r in rows),  # every row judged as its protocol asks (else: notes)
        "notes": list(notes),  # why a row is not complete (fewer training seeds, a cap)
        "wall_seconds": seconds,
        "rows": rows,  # one per task, split and policy
    }


def results_of(doc: dict) -> list[Result]:
    """The rows of a document (:func:`load`) as :class:`Result`, each with its recorded summary."""
    return [
        Result(
            task=row["task"],
            policy=row["policy"],
            kind=row["kind"],
            level=row["level"],
            runs=[
                Run(
                    source=run["source"],
                    training_seed=run.get("training_seed"),
                    agent_steps=run.get("agent_steps"),
                    sha256=run.get("sha256"),
                    returns=run["returns"],
                    successes=run["successes"],
                    cycles=run["cycles"],
                    seeds=list(row["world_seeds"]),
                    metrics=run.get("metrics", []),
                    seconds=run["seconds"],
                )
                for run in row["runs"]
            ],
            group=row["group"],
            split=row["split"],
            about=row["about"],
            env=row["env"],
            recipe=row["recipe"],
            complete=row["complete"],
            recorded=row["summary"],
            training=row["training"],
            declared=row["declared"],
        )
        for row in doc["rows"]
    ]


def markdown(doc: dict) -> str:
    """A document as its table page (``results.md``, ``benchmark.md``): what was judged, the table
    of its rows with 95 % intervals (a protocol's splits and worlds as columns), each training
    seed of a group on its own, what the intervals are, the settings of an evaluation and the notes."""
    results = results_of(doc)
    commit = f"proteo {doc['proteo_version'] or 'unknown'}, commit {(doc['commit'] or 'unknown')[:12]}"
    if doc["judgement"] == "benchmark":
        head = (
            f"Benchmark {doc['protocol']} ({doc['protocol_file']}, sha256 {doc['protocol_sha256'][:12]}); {commit}; "
            f"{'complete' if doc['complete'] else 'NOT complete (see the notes)'}."
        )
        columns = BENCHMARK_COLUMNS
    else:
        seeds = results[0].world_seeds if results else []
        worlds = f"worlds {seeds[0]}..{seeds[-1]}" if seeds else "no worlds"
        head = f"Evaluation (proteo eval) on {worlds}; {commit}."
        columns = EVALUATION_COLUMNS
    lines = [head, "", markdown_table(results, columns)]
    each = [one for r in results if r.group for one in r.each_run()]
    if each:
        lines += [
            "",
            "Each training seed on its own (the rows above summarise them):",
            "",
            markdown_table(each, columns),
        ]
    lines += ["", INTERVALS]
    if doc["judgement"] == "evaluation":
        settings = {task_name(r.task): r.env for r in results}
        lines += ["", f"Settings per task: {json.dumps(settings)}"]
    if doc["notes"]:
        lines += ["", "Notes:", "", *[f"- {n}" for n in doc["notes"]]]
    return "\n".join(lines) + "\n"


def write(doc: dict, out_dir, *, plots: bool = False) -> dict:
    """Write ``doc`` into ``out_dir`` as ``NAME.json`` and ``NAME.md`` (:data:`FILE_NAMES`), and
    (``plots``, an evaluation) ``eval.png``; returns ``doc``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = FILE_NAMES[doc["judgement"]]
    (out / f"{name}.json").write_text(json.dumps(doc, indent=1, default=float) + "\n")
    (out / f"{name}.md").write_text(markdown(doc))
    if plots and doc["judgement"] == "evaluation":
        plot(results_of(doc), out / "eval.png")
    return doc


def load(path, field: str = "--from-results") -> dict:
    """The document at ``path`` in the current version: a ``results.json`` or ``benchmark.json``
    of this schema, of ``proteo-benchmark-results`` version 1, or a ``results.json`` from before
    (see the module docstring). Anything else, or rows whose episodes do not add up (returns,
    successes and cycles of different lengths, or none), is one :class:`ConfigError` naming the
    file as ``field``."""
    p = Path(path)
    try:
        data = json.loads(p.read_text())
        version = (data.get("schema"), data.get("schema_version"))
        if version == (SCHEMA, SCHEMA_VERSION):
            doc = data
        elif version == (V1_SCHEMA, 1):
            doc = _from_benchmark_v1(data)
        elif "schema" not in data and "results" in data:
            doc = _from_evaluation_v1(data)
        else:
            raise ValueError(f"schema {version[0]!r} version {version[1]!r}")
        results = results_of(doc)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise ConfigError(
            f"{field}={str(p)!r} is not allowed ({type(error).__name__}: {error}); allowed: a results.json or "
            f"benchmark.json written by proteo eval (schema {SCHEMA} version {SCHEMA_VERSION} or earlier)"
        ) from None
    for r in results:
        for run in r.runs:
            if len({len(run.returns), len(run.successes), len(run.cycles)}) != 1 or not run.returns:
                raise ConfigError(
                    f"{field}={str(p)!r}: the row {r.task} / {r.policy} has returns, successes and cycles of "
                    f"lengths {len(run.returns)}, {len(run.successes)}, {len(run.cycles)}; allowed: one of each per "
                    "episode"
                )
    return doc


def _from_benchmark_v1(data: dict) -> dict:
    """A ``proteo-benchmark-results`` version 1 document in the current version. Rows judged
    before entrants have no ``training``: it is read from the kind and the recipe."""
    rows = []
    for row in data["rows"]:
        training = row.get("training") or (
            "reference" if row["kind"] in ("hand-coded", "random") else "protocol" if row.get("recipe") else "unchecked"
        )
        rows.append({**row, "training": training, "group": training != "reference", "declared": row.get("declared")})
    return {**data, "schema": SCHEMA, "schema_version": SCHEMA_VERSION, "judgement": "benchmark",
            "deterministic": False, "rows": rows}  # fmt: skip


def _from_evaluation_v1(data: dict) -> dict:
    """A ``results.json`` from before this format in the current version: its rows (one per run,
    with its group's ``group`` label) gathered into one row per policy or group, at the place of
    its first run; levels ``full`` where not recorded; the summaries computed again."""
    fields = {f.name for f in dataclasses.fields(Run)}
    results: list[Result] = []
    groups: dict = {}
    for row in data["results"]:
        run = Run(**{k: v for k, v in row.items() if k in fields})
        label = row.get("group") or ""
        result = groups.get((row["task"], label)) if label else None
        if result is None:
            result = Result(
                row["task"],
                label or row["policy"],
                row["kind"],
                row.get("level", "full"),
                group=bool(label),
                env=data["settings"].get(task_name(row["task"])) or {},
            )
            results.append(result)
            if label:
                groups[(row["task"], label)] = result
        result.runs.append(run)
    doc = document(results, judgement="evaluation", seconds=0.0, deterministic=data["deterministic"])
    return {**doc, "proteo_version": None, "commit": None, "created": None}


def rerender(path, out, *, plots: bool = True, pages=()) -> list[Result]:
    """Write the document at ``path`` (:func:`load`) into ``out`` again in the current format, its
    table page and (``plots``) ``eval.png`` with it, without playing an episode, and publish its
    tables into ``pages`` (:func:`~training.judging.report.publish_evaluation`). Every page is
    checked before anything is written. Returns the rows."""
    doc = load(path)
    results = results_of(doc)
    texts = {Path(f): filled(f, page_tables(results, out), PUBLISH_END) for f in pages}
    write(doc, out, plots=plots)
    for f, text in texts.items():
        f.write_text(text)
    return results
