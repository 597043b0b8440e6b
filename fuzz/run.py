"""Fuzzing campaign of the log readers through the entry point of ``undertow info``.

Each input is a mutation of a seed in ``fuzz/corpus/`` (small files derived from the real A50
recordings, a simulated ROS 2 bag, a simulated MAVLink telemetry log and the head of the real
ArduSub dataflash log ``ardusub_small.BIN``): byte flips, truncations, block overwrites, line edits,
field-level JSON mutations (huge integers, infinities, NaN, wrong types, absurd nesting),
YAML mutations of the files beside a ROS 2 bag (``undertow.yaml``, ``metadata.yaml``) and
bag-byte mutations; plus a named pipe and an empty file. Every input runs in a forked child
through :func:`undertow.commands.data.info_file` with a per-input timeout, and a sample also runs as
the ``undertow info`` command in a subprocess. The outcome of each input is one of:

- ``ok``: read without a warning; ``ok-with-warnings``: read, with reader warnings (bad data
  skipped and counted);
- ``user-error``: an ``UndertowError`` of ONE line (exit code 1 for the command);
- ``traceback``: any other exception (or a multi-line user error, or a numpy warning leaking);
- ``hang``: no answer within the timeout; ``crash``: the child died without answering.

Prints one JSON object of counts by outcome (and writes every failing input to ``--save`` with
its traceback). Exit code 0 when there is no traceback, hang or crash.

    .venv/bin/python fuzz/run.py --inputs 10000 --jobs 2 --seed 0
"""

from __future__ import annotations

import argparse
import json
import os
import random
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

import yaml

from undertow.commands.data import info_file  # imported once, before the children are forked
from undertow.errors import UndertowError

HERE = Path(__file__).resolve().parent
CORPUS = HERE / "corpus"
FAILURES = ("traceback", "hang", "crash")

# values a field can be replaced with: the failures met in readers of untrusted input
INTERESTING = [
    10**400,
    -(10**30),
    2**63,
    1e308,
    -1e308,
    float("inf"),
    float("-inf"),
    float("nan"),
    None,
    "",
    "sea",
    "1e999",
    True,
    0,
    -1,
    [],
    {},
    [1, 2],
    [[1, 2], [3, 4]],
    {"a": 1},
    "\u0000",
]


# -- mutators: each takes (rng, data bytes) and returns bytes -----------------------------------


def flip_bytes(rng: random.Random, data: bytes) -> bytes:
    out = bytearray(data)
    for _ in range(rng.choice((1, 1, 2, 4, 16))):
        if out:
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
    return bytes(out)


def set_bytes(rng: random.Random, data: bytes) -> bytes:
    out = bytearray(data)
    if out:
        i = rng.randrange(len(out))
        n = rng.choice((1, 4, 8, 64, 512))
        fill = rng.choice((b"\x00", b"\xff", b"\x7f", bytes([rng.randrange(256)])))
        out[i : i + n] = fill * len(out[i : i + n])
    return bytes(out)


def truncate(rng: random.Random, data: bytes) -> bytes:
    return data[: rng.randrange(len(data) + 1)] if data else data


def splice(rng: random.Random, data: bytes) -> bytes:
    """Duplicate or delete a block (shifts every later offset of a binary file)."""
    if len(data) < 2:
        return data
    i, n = rng.randrange(len(data)), rng.choice((1, 7, 100, 4096))
    return (
        data[:i] + data[i : i + n] * 2 + data[i + n :]
        if rng.random() < 0.5
        else data[:i] + data[i + n :]
    )


BYTE_MUTATORS = (flip_bytes, flip_bytes, set_bytes, truncate, splice)


def _paths(obj, prefix=()):
    """Every key path of a nested JSON/YAML value."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, (*prefix, i))


def _set(obj, path, value):
    if not path:
        return value
    target = obj
    for key in path[:-1]:
        target = target[key]
    if value is _DELETE:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return obj


_DELETE = object()


def mutate_value(rng: random.Random, obj):
    """One field of ``obj`` replaced, deleted or nested absurdly deep; or the whole replaced."""
    paths = list(_paths(obj))
    path = rng.choice(paths)
    r = rng.random()
    if r < 0.1 and path:
        return _set(obj, path, _DELETE)
    if r < 0.15:
        return _set(obj, path, "[" * 100_000)  # becomes nested JSON once dumped raw (below)
    value = rng.choice(INTERESTING)
    if isinstance(value, list | dict):
        value = json.loads(json.dumps(value))
    return _set(obj, path, value)


def mutate_json_lines(rng: random.Random, data: bytes) -> bytes:
    lines = data.decode("utf-8", "replace").splitlines()
    if not lines:
        return data
    r = rng.random()
    i = rng.randrange(len(lines))
    if r < 0.55:
        for _ in range(rng.choice((1, 1, 3))):
            i = rng.randrange(len(lines))
            try:
                obj = json.loads(lines[i])
            except (ValueError, RecursionError):  # a line an earlier mutation broke
                continue
            text = json.dumps(mutate_value(rng, obj))
            lines[i] = text.replace('"' + "[" * 100_000 + '"', "[" * 100_000)
    elif r < 0.65:
        lines[i] = "[" * rng.choice((1000, 100_000)) + "]" * rng.choice((0, 1000))
    elif r < 0.75:  # every position report given a non-finite time
        bad = rng.choice(('"ts": NaN', '"ts": Infinity', '"ts": null', '"ts": 1e999'))
        lines = [_replace_ts(line, bad) for line in lines]
    elif r < 0.85:
        lines.insert(i, lines[rng.randrange(len(lines))])
    elif r < 0.9:
        del lines[i]
    else:
        lines[i] = rng.choice(("{}", "[]", "null", "1", '"x"', '{"type": "position_local"}'))
    return ("\n".join(lines) + "\n").encode()


def _replace_ts(line: str, bad: str) -> str:
    try:
        obj = json.loads(line)
    except (ValueError, RecursionError):
        return line
    if isinstance(obj, dict) and obj.get("type") == "position_local":
        obj["ts"] = 0
        return json.dumps(obj).replace('"ts": 0', bad)
    return line


def mutate_yaml(rng: random.Random, data: bytes) -> bytes:
    try:
        obj = yaml.safe_load(data)
    except (yaml.YAMLError, RecursionError):
        return flip_bytes(rng, data)
    r = rng.random()
    if r < 0.1:
        obj = rng.choice(([1, 2], "text", 3, None, [obj]))
    elif r < 0.2 and isinstance(obj, dict):
        obj.setdefault("metadata", {})
        if isinstance(obj["metadata"], dict):
            obj["metadata"]["water_density_kg_m3"] = rng.choice(("sea", -1, 0, 10**400, None))
    elif r < 0.3:
        return flip_bytes(rng, data)
    else:
        for _ in range(rng.choice((1, 2, 4))):
            obj = mutate_value(rng, obj)
            if rng.random() < 0.2 and isinstance(obj, dict) and obj:  # a non-string key
                obj[rng.choice((1, 2.5, None, True))] = obj.pop(next(iter(obj)), None)
    text = yaml.safe_dump(obj, sort_keys=False, allow_unicode=True)
    return text.replace("'" + "[" * 100_000 + "'", "[" * 1000).encode()


# -- inputs --------------------------------------------------------------------------------------


def _seed_files():
    """(name, kind, path) of every seed: JSON lines, ROS 1 bags, ROS 2 bag folders, MAVLink
    telemetry logs, ArduPilot dataflash logs."""
    seeds = []
    for path in sorted(CORPUS.iterdir()):
        if path.suffix == ".txt":
            seeds.append((path.name, "json", path))
        elif path.suffix == ".bag":
            seeds.append((path.name, "ros1", path))
        elif path.suffix == ".tlog":
            seeds.append((path.name, "tlog", path))
        elif path.suffix.lower() == ".bin":
            seeds.append((path.name, "dataflash", path))
        elif path.is_dir():
            seeds.append((path.name, "ros2", path))
    return seeds


def make_input(rng: random.Random, seeds, workdir: Path, index: int) -> tuple[Path, str]:
    """Write one mutated input under ``workdir``; (path to read, mutation label)."""
    name, kind, seed = rng.choices(seeds, weights=[_WEIGHT[s[1]] for s in seeds])[0]
    if kind == "json":
        mut = rng.choice((mutate_json_lines, mutate_json_lines, mutate_json_lines, *BYTE_MUTATORS))
        out = workdir / f"in{index}.txt"
        out.write_bytes(mut(rng, seed.read_bytes()))
        return out, f"{name}:{mut.__name__}"
    if kind in _BINARY_SUFFIX:
        mut = rng.choice(BYTE_MUTATORS)
        out = workdir / f"in{index}.{_BINARY_SUFFIX[kind]}"
        out.write_bytes(mut(rng, seed.read_bytes()))
        return out, f"{name}:{mut.__name__}"
    out = workdir / f"in{index}"
    shutil.copytree(seed, out)
    target = rng.choice(("undertow.yaml", "metadata.yaml", "mcap", "mcap"))
    file = next(out.glob("*.mcap")) if target == "mcap" else out / target
    mut = rng.choice(BYTE_MUTATORS) if target == "mcap" else mutate_yaml
    file.write_bytes(mut(rng, file.read_bytes()))
    return out, f"{name}/{target}:{mut.__name__}"


_WEIGHT = {"json": 3.0, "ros1": 1.0, "ros2": 1.5, "tlog": 1.0, "dataflash": 1.0}
_BINARY_SUFFIX = {"ros1": "bag", "tlog": "tlog", "dataflash": "BIN"}


def special_inputs(workdir: Path) -> list[tuple[Path, str]]:
    """Inputs no mutation makes: a named pipe, an empty file, a directory of junk."""
    fifo = workdir / "pipe.txt"
    os.mkfifo(fifo)
    (workdir / "empty.bag").write_bytes(b"")
    (workdir / "empty.txt").write_bytes(b"")
    junk = workdir / "junk_dir"
    junk.mkdir()
    (junk / "metadata.yaml").write_text("- not\n- a mapping\n")
    return [
        (fifo, "special:named_pipe"),
        (workdir / "empty.bag", "special:empty_bag"),
        (workdir / "empty.txt", "special:empty_json"),
        (junk, "special:metadata_list"),
    ]


# -- running one input ---------------------------------------------------------------------------


def _classify(path: Path) -> dict:
    """Run info_file on ``path`` in this (child) process: outcome and detail."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            info_file(path)
            outcome, detail = "ok", ""
        except UndertowError as exc:
            text = str(exc)
            outcome = "user-error" if text and "\n" not in text else "traceback"
            detail = text
        except BaseException:  # noqa: BLE001 - the campaign counts every escape
            outcome, detail = "traceback", traceback.format_exc()
    leaked = [str(w.message) for w in caught if not issubclass(w.category, UserWarning)]
    if leaked and outcome != "traceback":
        outcome, detail = "traceback", "leaked warning: " + leaked[0]
    elif outcome == "ok" and caught:
        outcome = "ok-with-warnings"
    return {"outcome": outcome, "detail": detail[-4000:]}


def run_forked(path: Path, timeout: float):
    """Start a child classifying ``path``; (pid, read fd)."""
    rfd, wfd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(rfd)
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 2)
            result = _classify(path)
        except BaseException:  # noqa: BLE001
            result = {"outcome": "traceback", "detail": traceback.format_exc()}
        os.write(wfd, json.dumps(result).encode())
        os._exit(0)
    os.close(wfd)
    return pid, rfd, time.monotonic() + timeout


def _collect(pid: int, rfd: int) -> dict:
    chunks = []
    while chunk := os.read(rfd, 65536):
        chunks.append(chunk)
    os.close(rfd)
    _, status = os.waitpid(pid, 0)
    if not chunks:
        return {"outcome": "crash", "detail": f"child exit status {status}"}
    return json.loads(b"".join(chunks))


def _kill(pid: int, rfd: int) -> dict:
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    os.close(rfd)
    return {"outcome": "hang", "detail": "no answer within the timeout"}


def run_pool(inputs, jobs: int, timeout: float, on_result) -> None:
    """Classify ``inputs`` ((path, label) iterator) with up to ``jobs`` children at a time."""
    running: dict[int, tuple] = {}  # read fd -> (pid, deadline, path, label)
    inputs = iter(inputs)
    exhausted = False
    while running or not exhausted:
        while not exhausted and len(running) < jobs:
            item = next(inputs, None)
            if item is None:
                exhausted = True
                break
            pid, rfd, deadline = run_forked(item[0], timeout)
            running[rfd] = (pid, deadline, *item)
        if not running:
            break
        wait = max(0.0, min(v[1] for v in running.values()) - time.monotonic())
        ready, _, _ = select.select(list(running), [], [], wait)
        for rfd in ready:
            pid, _, path, label = running.pop(rfd)
            on_result(path, label, _collect(pid, rfd))
        now = time.monotonic()
        for rfd in [fd for fd, v in running.items() if v[1] < now]:
            pid, _, path, label = running.pop(rfd)
            on_result(path, label, _kill(pid, rfd))


def cli_sample(paths: list[Path], timeout: float) -> Counter:
    """``undertow info PATH`` as a subprocess: exit 0 or 1 with no traceback, else a failure."""
    exe = Path(sys.executable).with_name("undertow")
    counts: Counter = Counter()
    for path in paths:
        try:
            proc = subprocess.run(
                [str(exe), "info", str(path)], capture_output=True, text=True, timeout=timeout
            )
        except subprocess.TimeoutExpired:
            counts["hang"] += 1
            continue
        bad = "Traceback" in proc.stderr or proc.returncode not in (0, 1)
        counts["traceback" if bad else f"exit-{proc.returncode}"] += 1
    return counts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=int, default=10_000, help="mutated inputs (10000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the mutations")
    parser.add_argument("--jobs", type=int, default=2, help="children at a time (2)")
    parser.add_argument("--timeout", type=float, default=20.0, help="seconds per input (20)")
    parser.add_argument("--cli-sample", type=int, default=40, help="inputs also run as the command")
    parser.add_argument("--save", type=Path, default=None, help="folder for failing inputs")
    args = parser.parse_args(argv)
    rng, pick = random.Random(args.seed), random.Random(args.seed + 1)
    seeds = _seed_files()
    counts: Counter = Counter()
    failures: list[dict] = []
    sample: list[Path] = []
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="undertow-fuzz-") as tmp:
        workdir = Path(tmp)

        def generate():
            yield from special_inputs(workdir)
            for i in range(args.inputs):
                yield make_input(rng, seeds, workdir, i)

        def on_result(path: Path, label: str, result: dict) -> None:
            counts[result["outcome"]] += 1
            done = sum(counts.values())
            if done % 1000 == 0:
                print(f"{done} inputs: {dict(counts)}", file=sys.stderr, flush=True)
            if result["outcome"] in FAILURES:
                failures.append({"input": label, **result})
                if args.save is not None:
                    args.save.mkdir(parents=True, exist_ok=True)
                    dest = args.save / f"{len(failures):04d}_{path.name}"
                    if path.is_dir():
                        shutil.copytree(path, dest)
                    elif path.is_file():
                        shutil.copy(path, dest)
                    (args.save / f"{len(failures):04d}.txt").write_text(
                        f"{label}\n{result['detail']}"
                    )
            if len(sample) < args.cli_sample and path.is_file() and pick.random() < 0.05:
                keep = workdir / "sample"
                keep.mkdir(exist_ok=True)
                sample.append(Path(shutil.copy(path, keep / path.name)))
            elif path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            elif path.is_file() and not path.is_fifo():
                path.unlink()

        run_pool(generate(), args.jobs, args.timeout, on_result)
        cli = cli_sample(sample, args.timeout)
    report = {
        "inputs": sum(counts.values()),
        "seed": args.seed,
        "seconds": round(time.monotonic() - started, 1),
        "outcomes": {k: counts.get(k, 0) for k in ("ok", "ok-with-warnings", "user-error")}
        | {k: counts.get(k, 0) for k in FAILURES},
        "cli_sample": dict(cli),
        "failures": [f["input"] + ": " + f["detail"].strip().splitlines()[-1] for f in failures][
            :20
        ],
    }
    print(json.dumps(report, indent=2))
    bad = sum(counts[k] for k in FAILURES) + cli.get("traceback", 0) + cli.get("hang", 0)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
