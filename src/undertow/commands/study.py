"""`undertow characterize`, `reproduce` and `demo` as library functions: paths and settings in,
a result object with the warnings and facts the command prints out.

    >>> result = characterize_files(["runs/calm/log", "runs/a10/log"], out="profile.yaml")
    ...                                                              # doctest: +SKIP
    >>> result.warnings, result.to_dict()["profile"]                  # doctest: +SKIP
    >>> study = reproduce("results_mc", seeds=10)                     # doctest: +SKIP
    >>> study.markdown, study.failures, study.report                  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .._util.atomic import check_output_file
from ..errors import UndertowError
from ..estimation.characterize import Characterization, characterize
from ..settings import Settings
from ..study.peers import PeerSettings
from ..study.pipeline import StudySettings
from ..study.runner import StudyResult, run_study
from .common import as_settings, collect_warnings, load_log


@dataclass
class CharacterizeResult:
    """What `undertow characterize` prints: one row per run (the paper's Table I), the noise
    profile for `undertow localize` (written to ``profile_path`` when given) and the warnings:
    those raised while reading and characterizing, then one per note a run raised
    (``"<source>: <note>"``)."""

    characterization: Characterization
    profile_path: Path | None = None
    warnings: list[str] = field(default_factory=list)

    def rows(self) -> list[dict]:
        return self.characterization.table()

    def to_dict(self) -> dict:
        """The ``--json`` output: the runs and the noise profile."""
        return {"runs": self.rows(), "profile": self.characterization.profile.to_dict()}


def characterize_files(
    paths: Sequence[str | Path],
    settings: Settings | str | Path | None = None,
    *,
    topics: str | Path | None = None,
    out: str | Path | None = None,
) -> CharacterizeResult:
    """Wave amplitude and frequency (wave probe; without one, the onboard estimate of
    :mod:`undertow.seastate`, which is also shown next to the probe's for comparison)
    and the DVL noise per axis during the waves,
    about the true motion (the paper's Table I), plus the barometer's wave-induced depth noise,
    of the logs at ``paths``; a calm run among them is the reference whose noise is subtracted.

    ``settings``: a :class:`~undertow.settings.Settings`, a settings YAML path or None
    (defaults); ``topics``: a topic map YAML overriding the settings' topics. With ``out``, the
    noise profile is written there (YAML for `undertow localize --profile`)."""
    settings = as_settings(settings)
    if out is not None:
        check_output_file(out)
    caught: list[str] = []
    with collect_warnings(caught):
        result = characterize([load_log(p, topics, settings) for p in paths])
    profile_path = None
    if out is not None:
        profile_path = Path(out)
        result.profile.to_yaml(profile_path)
    notes = [f"{run.source}: {note}" for run in result.runs for note in run.notes]
    return CharacterizeResult(result, profile_path, caught + notes)


def reproduce(
    out_dir: str | Path = "results",
    *,
    seeds: int = 1,
    first_seed: int = 0,
    scheduler: str | None = None,
    rock_survey: bool = True,
    map_scenarios: bool = True,
    peers: bool = True,
    peer_time_cap_s: float | None = None,
    peer_scenarios: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> StudyResult:
    """The paper's experiments end to end for the seeds ``first_seed .. first_seed + seeds - 1``:
    simulate, characterize, localize (4 variants), map (CSM, BKI, adaptive BKI), evaluate;
    tables with the paper's values, figures and ``report.html`` under ``out_dir``
    (:func:`undertow.study.runner.run_study`; ``scheduler`` runs the seeds after the first).
    ``map_scenarios``: also Table IV on the mapping scenarios (mhl-basin, field-survey);
    ``peers``: also the peers table (:mod:`undertow.study.peers`: the UKF beside the factor
    graph, iSAM2 and the InEKF), the batch factor graph capped at ``peer_time_cap_s`` wall
    seconds per run (default :data:`~undertow.study.peers.FACTOR_GRAPH_CAP_S`; 0 leaves it
    out; ``peer_scenarios``: its scenarios, default
    :data:`~undertow.study.peers.PEER_SCENARIOS`)."""
    if seeds < 1:
        raise UndertowError("--seeds must be at least 1")
    if first_seed < 0:
        raise UndertowError(f"--first-seed must be >= 0, got {first_seed}")
    settings = StudySettings(rock_survey="rock-survey" if rock_survey else None)
    if not map_scenarios:
        settings = dataclasses.replace(settings, map_scenarios=())
    if peers:
        settings = dataclasses.replace(
            settings, peers=peer_settings(peer_time_cap_s, peer_scenarios)
        )
    return run_study(
        out_dir,
        seeds=list(range(first_seed, first_seed + seeds)),
        scheduler=scheduler,
        settings=settings,
        progress=progress,
    )


def peer_settings(
    time_cap_s: float | None = None, scenarios: Sequence[str] | None = None
) -> PeerSettings:
    """The peers table's settings: the batch factor graph capped at ``time_cap_s`` (s), the
    ``scenarios`` (built-in scenario names) if given."""
    changes = {}
    if time_cap_s is not None:
        if time_cap_s < 0:
            raise UndertowError(f"--peer-time-cap must be >= 0 s, got {time_cap_s:g}")
        changes["time_cap_s"] = {"factor-graph": float(time_cap_s)}
    if scenarios is not None:
        from ..sim import list_scenarios

        known = set(list_scenarios())
        unknown = [s for s in scenarios if s not in known]
        if unknown or not scenarios:
            raise UndertowError(
                f"--peer-scenarios: unknown scenario(s) {', '.join(unknown) or '(none given)'}; "
                f"known: {', '.join(sorted(known))}"
            )
        changes["scenarios"] = tuple(scenarios)
    return PeerSettings(**changes)


def demo(
    out_dir: str | Path = "results", progress: Callable[[str], None] | None = None
) -> StudyResult:
    """The main job with its defaults: :func:`reproduce` with one seed (seed 0), without the
    mapping scenarios and the peers table (they run in ``undertow reproduce``)."""
    return reproduce(out_dir, progress=progress, map_scenarios=False, peers=False)
