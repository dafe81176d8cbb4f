"""What ``flexvib run SCENE [--set PATH=VALUE ...] [--only STUDY ...]`` runs, as one object
(:class:`ScenePlan`): the scene read (a built-in name or a .toml file), the ``--set`` values put into
its tables before they are checked, its ``[studies]`` table (declared, or the defaults) checked key by
key (documented in docs/studies.md), the studies narrowed by ``--only``, and the problem built.

``--set`` replaces (or adds) the value at a dotted key path of the scene file, e.g.
``links.coupler.thickness=2e-3`` or ``studies.sweep.count=50``, before the scene is checked, so the
scene's own checks judge the new value (and name its key). VALUE is a TOML value (``2e-3``, ``true``,
``"speed"``, ``[60.0, 185.0]``); a bare word that is not one is taken as a string. The tables on the
path must exist: a misspelt table is refused, naming the path and the keys that are there. The
``studies.*`` paths apply to the studies table after the defaults are filled in, so that they reach a
scene without a ``[studies]`` table too.
"""

from __future__ import annotations

import argparse
import logging
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from .._budget import check_tolerance
from .._errors import StudiesError, UsageError
from .._kind import COMMON_KEYS, integer, kind_named, kinds, reject_unknown
from .._numerics import DEFAULT_SCHEME, study_scheme
from .._problem import SPEED

logger = logging.getLogger(__name__)

__all__ = ["MATHIEU", "ScenePlan", "apply_overrides", "default_table", "parse_set", "plan"]

#: A built-in non-mechanism scene: the damped, forced Mathieu oscillator (studies.mathieu_problem),
#: whose every number is known independently; small and fast, for trying the command out. Its
#: studies are each registered kind's ``demo`` table.
MATHIEU = "mathieu"
#: Steps per period of the mathieu scene's studies (each kind's ``demo`` table may set its own).
MATHIEU_STEPS = 128
#: The scene table the ``studies.*`` paths of ``--set`` address.
STUDIES = "studies"


@dataclass(frozen=True)
class ScenePlan:
    """The run a scene and the command line declare: ``scene`` (as named), ``problem`` (a
    ``MechanismProblem``, or the Mathieu ``PeriodicProblem``), ``common`` (the ``[studies]`` table's
    own keys, checked: ``n_steps``, ``observables``, ``scheme``) and ``studies`` ({kind: options},
    the declared studies named by ``--only``, each checked with its defaults filled in: what the
    kind's ``run`` takes)."""

    scene: str
    problem: Any
    common: Mapping[str, Any]
    studies: Mapping[str, Mapping[str, Any]]

    @classmethod
    def read(cls, scene: str, sets: Sequence[tuple[str, Any]] = (), *,
             only: Sequence[str] | None = None) -> "ScenePlan":
        """The plan of ``scene`` (a built-in name or a .toml path) with the ``--set`` values
        ``(path, value)`` of ``sets`` applied before anything is checked, and only the studies named
        in ``only`` (all when None). A scene without a ``[studies]`` table gets each kind's default
        table; a ``[studies]`` table that declares nothing is an error listing the kinds."""
        scene_sets = [(path, value) for path, value in sets if path.split(".")[0] != STUDIES]
        studies_sets = [(path.partition(".")[2], value) for path, value in sets
                        if path.split(".")[0] == STUDIES]
        if any(not path for path, _ in studies_sets):
            raise UsageError("--set studies: set a key of a study table, e.g. studies.sweep.count=50")
        if scene == MATHIEU:
            if scene_sets:
                path, value = scene_sets[0]
                raise UsageError(f"--set {path}={value!r}: the built-in {MATHIEU} scene has no scene table to "
                                 f"change; set keys of its studies (studies.*)")
            from .._problem import mathieu_problem

            common, declared = plan(apply_overrides(mathieu_table(), studies_sets, prefix=f"{STUDIES}."))
            problem = mathieu_problem()
        else:
            from .._mechanism import MechanismProblem

            mechanism = _mechanism(scene, scene_sets)
            # "no [studies] table" runs the default set; a [studies] table that declares nothing is
            # a mistake that plan() reports with the list of kinds. The studies' speed is the
            # motion's fundamental frequency 2 pi / period (the crank speed).
            table = (dict(mechanism.studies) if STUDIES in (mechanism.spec or {})
                     else default_table(2.0 * math.pi / mechanism.period))
            common, declared = plan(apply_overrides(table, studies_sets, prefix=f"{STUDIES}."))
            problem = MechanismProblem.from_mechanism(mechanism, parameter_paths=parameters_needed(declared),
                                                      observables=common["observables"])
        return cls(scene=scene, problem=problem, common=common, studies=_only(declared, only))

    def guard(self, *, force: bool = False, workers: int = 1, result_file: str | Path | None = None) -> list:
        """The resource guard's estimates of the studies (``studies.guard``): a study above the
        limits is refused unless ``force``; studies complete in ``result_file`` (the file the run
        resumes) are not estimated, a grid partly saved there only for its missing points."""
        from .._guard import guard

        return guard(self.problem, self.studies, force=force, workers=workers, result_file=result_file)

    def run(self, path: str | Path, **options: Any) -> tuple[dict[str, Any], dict[str, str]]:
        """Run the studies into the result file ``path`` (``studies.cli._run.run_plan``: its
        ``executor``, ``progress``, ``overwrite``, ``warm_up`` options); ``(results, failures)``."""
        from ._run import run_plan

        return run_plan(self.problem, self.studies, str(path), **options)


def _mechanism(scene: str, sets: Sequence[tuple[str, Any]]):
    """``mechanisms.load(scene)`` with the ``--set`` values of scene keys put into the parsed table
    before it is checked and built."""
    import mechanisms

    path = Path(scene)
    if path.suffix == ".toml" and not path.exists():
        raise UsageError(f"scene file {scene!r} does not exist")
    if path.exists():
        _check_scene_file(path)
    try:
        if not sets:
            return mechanisms.load(scene)
        if path.suffix == ".toml" or path.exists():
            try:
                spec = tomllib.loads(path.read_text(encoding="utf-8"))
            except tomllib.TOMLDecodeError as error:
                raise mechanisms.MechanismError(f"{scene}: not valid TOML: {error}") from None
            source = str(path)
        else:
            spec, source = mechanisms.load(scene).spec, f"scene {scene!r}"  # built-in scenes are valid
    except OSError as error:  # unreadable (permissions, a device): one line, exit 2
        raise UsageError(f"scene file {scene!r} cannot be read: {error.strerror or error}") from None
    changed = ", ".join(f"{p}={v!r}" for p, v in sets)
    return mechanisms.build(apply_overrides(spec, sets), source=f"{source} with --set {changed}")


#: The largest scene file read (bytes): the shipped scenes are a few kB; a scene is data the TOML
#: parser reads whole and every result file keeps.
MAX_SCENE_BYTES = 1 << 20


def _check_scene_file(path: Path) -> None:
    """A scene path that exists must be a regular file (not a folder or a device such as /dev/zero),
    of at most ``MAX_SCENE_BYTES``, and TOML nested no deeper than the parser can follow."""
    import mechanisms

    if not path.is_file():
        kind = "a folder" if path.is_dir() else "not a regular file (a device or a pipe)"
        raise UsageError(f"scene {str(path)!r} is {kind}; give a .toml scene file or a built-in scene name "
                         f"(flexvib scenes)")
    size = path.stat().st_size
    if size > MAX_SCENE_BYTES:
        raise UsageError(f"scene file {str(path)!r} has {size} bytes; at most {MAX_SCENE_BYTES} (a scene "
                         f"is a few kB: keep long text out of it)")
    try:
        tomllib.loads(path.read_text(encoding="utf-8", errors="replace"))
    except RecursionError:
        raise mechanisms.MechanismError(f"{path}: not valid TOML: nested deeper than the parser follows "
                                        f"(arrays or tables within each other)") from None
    except (tomllib.TOMLDecodeError, OSError):
        pass   # the loader reports it in its own words


def _only(declared: Mapping[str, Any], only: Sequence[str] | None) -> dict[str, Any]:
    """The declared studies named by ``--only`` (all of them when None); an undeclared name is a
    ``UsageError`` listing the declared ones."""
    if not only:
        return dict(declared)
    unknown = [name for name in only if name not in declared]
    if unknown:
        raise UsageError(f"--only: the scene declares no study {unknown[0]!r} (declared: "
                         f"{', '.join(declared)})")
    return {name: options for name, options in declared.items() if name in only}


def mathieu_table() -> dict[str, Any]:
    """The ``[studies]`` table of the built-in ``mathieu`` scene: each registered kind's ``demo``
    table (kinds without one, such as the mechanism-only ones, are not in it)."""
    return {"n_steps": MATHIEU_STEPS,
            **{name: dict(kind.demo) for name, kind in kinds().items() if kind.demo is not None}}


# ---------------------------------------------------------------------------------------------------
# the [studies] table
# ---------------------------------------------------------------------------------------------------
def default_table(nominal_speed: float) -> dict[str, Any]:
    """The studies run for a scene without a ``[studies]`` table, each kind's default (steady state,
    a 100-point speed sweep and a 40-speed Campbell diagram from 0.2 to 4 times the scene's speed
    ``2 pi / period`` (rad/s), a 3-period nonlinear check)."""
    tables = {name: kind.default(nominal_speed) for name, kind in kinds().items()}
    return {name: table for name, table in tables.items() if table is not None}


def plan(table: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Check a ``[studies]`` table; returns ``(common, {kind: options})`` with the defaults filled in
    (options are what each kind's ``run`` takes: the keyword arguments of its study function)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[studies]: expected a table, got {table!r}")
    reject_unknown("studies", table, COMMON_KEYS + tuple(kinds()))
    n_steps = integer("studies", "n_steps", table.get("n_steps", 256), 4, even=True)
    observables = table.get("observables")
    if observables is not None and (not isinstance(observables, list) or not observables
                                    or not all(isinstance(s, str) for s in observables)):
        raise StudiesError(f"[studies] observables: expected a non-empty list of specs such as "
                           f"'coupler.deflection@0.5' (leave the key out for the default observables), "
                           f"got {observables!r}"[:400])
    scheme = table.get("scheme", DEFAULT_SCHEME)
    try:
        study_scheme(scheme)
    except StudiesError as error:
        raise StudiesError(f"[studies] {error}") from None
    tolerance = table.get("error_tolerance")
    if tolerance is not None:
        tolerance = check_tolerance(tolerance, "[studies] error_tolerance")
    common = {"n_steps": n_steps, "observables": None if observables is None else tuple(observables),
              "scheme": scheme}
    studies: dict[str, dict[str, Any]] = {}
    for name, kind in kinds().items():
        if name not in table:
            continue
        where = f"studies.{name}"
        options = table[name]
        if not isinstance(options, Mapping):
            raise StudiesError(f"[{where}]: expected a table, got {options!r}")
        reject_unknown(where, options, kind.keys)
        studies[name] = kind.check(where, options, n_steps)
        if tolerance is not None and (kind.schemes or "error_tolerance" in kind.keys):
            # the error budget's status rule (studies._budget); a kind's own table key wins
            studies[name].setdefault("error_tolerance", tolerance)
        if kind.schemes:  # part of the request, so a run with another scheme is another study
            studies[name]["scheme"] = scheme
        elif scheme != DEFAULT_SCHEME:
            logger.warning("[studies] scheme = %r: %s does not take the option; its linear solutions (a "
                           "shooting's start, a linear reference) use the default %r scheme", scheme, name,
                           DEFAULT_SCHEME)
    if not studies:
        raise StudiesError(f"[studies] declares no study; add at least one of the tables "
                           f"{', '.join(f'[studies.{k}]' for k in kinds())}")
    return common, studies


def parameters_needed(studies: Mapping[str, Mapping[str, Any]]) -> tuple[str, ...]:
    """The scene parameters (dotted paths, not ``speed``) the declared studies vary."""
    names = [path for name, options in studies.items() for path in kind_named(name).varies(options)]
    return tuple(dict.fromkeys(n for n in names if n != SPEED))


# ---------------------------------------------------------------------------------------------------
# --set PATH=VALUE
# ---------------------------------------------------------------------------------------------------
def parse_set(text: str) -> tuple[str, Any]:
    """``"PATH=VALUE"`` -> ``(PATH, value)``; the argparse type of ``--set``: a malformed one raises
    ``argparse.ArgumentTypeError``, whose message argparse prints after "argument --set:" (exit
    code 2; a ValueError would print only "invalid parse_set value")."""
    path, sep, raw = text.partition("=")
    path = path.strip()
    if not sep or not path or any(not part.strip() for part in path.split(".")):
        raise argparse.ArgumentTypeError(f"expected PATH=VALUE such as links.coupler.thickness=2e-3 (PATH "
                                         f"dotted scene keys), got {text!r}")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"value = {raw}")["value"]
    except tomllib.TOMLDecodeError:
        if not raw or any(c in raw for c in " \t[]{}\"',="):
            raise argparse.ArgumentTypeError(f"{path}: expected a TOML value (a number, true or false, a quoted "
                             f"string, an array [...]), got {raw!r}") from None
        value = raw  # a bare word: a string (`--set studies.sweep.parameter=speed`)
    return path, value


def apply_overrides(table: Mapping[str, Any], sets: Sequence[tuple[str, Any]], *,
                    prefix: str = "") -> dict[str, Any]:
    """A copy of ``table`` with each ``(path, value)`` of ``sets`` set (paths relative to ``table``,
    named with ``prefix`` in messages). Every table on a path must exist (else ``UsageError``
    naming the path and the keys there); the last key may be new (the scene's checks reject an
    unknown one and suggest the nearest)."""
    result = _copy_tables(table)
    for path, value in sets:
        node, parts = result, path.split(".")
        for depth, key in enumerate(parts[:-1]):
            child = node.get(key)
            if not isinstance(child, dict):
                where = prefix + ".".join(parts[:depth + 1])
                found = "no table" if child is None else f"a value ({child!r}), not a table,"
                raise UsageError(f"--set {prefix}{path}: the scene has {found} at {where!r} (keys "
                                 f"there: {', '.join(sorted(node)) or 'none'})")
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise UsageError(f"--set {prefix}{path}: that is a table; set one of its keys "
                             f"({', '.join(sorted(node[parts[-1]]))})")
        node[parts[-1]] = value
    return result


def _copy_tables(table: Mapping[str, Any]) -> dict[str, Any]:
    return {key: _copy_tables(value) if isinstance(value, Mapping) else value
            for key, value in table.items()}
