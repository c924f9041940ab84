"""Stored reference files (``.qref``): the references' calibrated stage, written once, read
instead of the reference logs.

A diagnosis against nominal reference flights (``--per-flight``, or held out with
``--reference``) first prepares, calibrates and self-checks the references
(:class:`quadsim.gap.calibrate.Calibrated`: the calibrated reference model, its noise model,
its discrepancy term and its self-check, the set-fits-the-vehicle check, the references'
notes). A stored reference file holds that stage, so the reference logs need not be at hand
(nor loaded) to judge a flight against them::

    python -m quadsim.gap --model crazyflie21 --reference nominal/*.csv.gz \\
        --write-reference nominal.qref --reference-source "our lab, 20 hover + figure-8s"
    python -m quadsim.gap --model crazyflie21 --per-flight new/*.csv.gz --reference nominal.qref
    python -m quadsim.gap --model crazyflie21 a.csv.gz b.csv.gz --holdout c.csv.gz \\
        --reference nominal.qref

``--write-reference OUT.qref`` needs ``--reference LOG...`` (the logs, not a ``.qref``);
with no ``LOG`` to judge it only writes the file; with ``LOG``\\ s it also judges them, in
either mode, against the stage it writes. ``--reference FILE.qref`` (one file with this
suffix, alone): the stage read from it, in both modes; the answers are those of
``--reference`` with the logs it was written from, bit for bit, as long as this quadsim
computes the stage as the one that wrote it did (below, "Staleness").

**A parameter set's shipped reference.** A built-in parameter set may ship one, written from
its own nominal flights: ``models/references/NAME.qref`` beside ``models/NAME.toml`` (in a
wheel: ``quadsim/_shipped/models/references``; :func:`shipped_reference`). With ``--model
NAME`` and no ``--reference``, held-out mode and ``--per-flight`` judge against it, and the
answer says so ("Judged against the set's own 20 nominal flights (shipped reference
crazyflie21.qref ...)"; JSON ``reference_file`` with ``"shipped": true``). ``--bare``
judges against the parameter set alone instead (held out: as before the set shipped one;
``--write-effects`` always does: its effect is added to ``--model``). The shipped file is
used only where it fits the run (:func:`mismatch`: the same parameter-set content, no
``--effects-file``, the same ``--effects`` and ``--window``); held out, a run it does not fit
is judged against the parameter set alone with a note saying why; ``--per-flight`` is
refused (one line) as without a reference. A set without a shipped file behaves as before.

**File format** (:data:`SCHEMA`, :data:`FORMAT`). Line 1: a JSON header (UTF-8, one line),
readable without unpickling (``python -m quadsim.gap.reffile FILE.qref`` prints it, as
does ``head -1 FILE.qref | python -m json.tool``)::

    schema        "quadsim.gap.reference/1"
    format        an integer, FORMAT of the quadsim that wrote it (below)
    quadsim       quadsim's version; code: quadsim.gap.calibrate.code_version() (information)
    written       UTC date and time (ISO 8601); command: the command line that wrote it
    source        free text (--reference-source): where the reference flights come from
    model         {"name", "sha256": params_hash of the parameter set}
    effects_file  null, or {"name", "sha256": effects_hash of its effects}
    effects       --effects (null: the whole library); window_s: --window (s)
    references    [{"file", "bytes", "sha256"}] of each reference log, as given
    command_references  the same for --command-reference
    count         reference flights; loaded: {"samples", "warnings", "notes"} of loading them
    judges        "speeds" (references with rotor speeds) or "commands" (command-only
                  references: below); absent in older files: "speeds"
    command_model null, or the command -> speed model of a "commands" file (below)
    stage         {"type", "encoding": "pickle/4", "bytes", "sha256"} of the rest of the file

then the stage, a Python pickle (protocol 4) of the :class:`~quadsim.gap.calibrate.Calibrated`.

**Command-only references** (``judges: "commands"``). Logs with the IMU and the motor
commands but no rotor speeds get speeds synthesised (:func:`quadsim.gap.logcheck.
synthesise_all`): references written with ``--reference CMD_LOGS... --command-reference
SPEED_LOGS...`` were calibrated on speeds synthesised by a command -> speed model fitted on
the ``--command-reference`` logs (:class:`~quadsim.gap.logcheck.CommandModel`); without
``--command-reference``, by the parameter set's motor map balanced rotor by rotor on the
references (:class:`~quadsim.gap.logcheck.BalancedModel`). That model is all a judged
command-only flight needs beyond the stage, so the header keeps it (``command_model``, JSON,
floats as ``float.hex``: exact; :func:`model_to_json`): ``{"type": "fitted", "a", "b", "c",
"v_ref", "tau", "rms", "samples", "source"}``, ``{"type": "motor_map", "tau", "rms",
"source"}`` (the run's parameter set's map: the same content, ``model``) or ``{"type":
"balanced", "factors", "model": ...}``. Against such a file a command-only log is judged
with no ``--command-reference`` (given, it is refused: the stage was calibrated with the
stored model), with the answers of the logs, bit for bit; a log with speeds is judged as it
is (as against the logs). Why no :data:`FORMAT` bump: the stage means what it meant (a
:class:`~quadsim.gap.calibrate.Calibrated` of the references as loaded and synthesised);
the header only gains two optional keys, a format-1 file without them is a "speeds" file,
and a quadsim that predates them reads a "commands" file as the logs without
``--command-reference`` would be read (a command-only log refused), never judging wrongly.
A set may ship one of each (``NAME.qref``, ``NAME_commands.qref``): the default picks the
file that fits the judged logs (every one with speeds: ``NAME.qref``; any without:
``NAME_commands.qref``, the only one that judges them all, one reference for the whole run;
with ``--command-reference``: ``NAME.qref`` as before).

**Refusals** (one line naming the file and the field, exit 2): a header that is not one
(a foreign file), another ``schema``, another ``format`` ("written by format 1, this quadsim
reads 2: write it again with `COMMAND`"), a stage shorter or other than the header says
(truncated, altered), a stage that names anything outside the allowed list (below), and a
file calibrated for another parameter set (``model``: compared by content,
:func:`params_hash`), other effects already in the model (``effects_file``), other
``--effects`` or another ``--window``. ``--write-reference`` writes to a temporary file
renamed into place (nothing half-written) and never over an input.

**Trust.** The stage is a pickle. It is read with a restricted unpickler
(:class:`_Restricted`): only quadsim's dataclasses, numpy's ``ndarray``, ``dtype`` and scalar
types and their reconstructors, ``pathlib``'s path classes and a few builtins and ``collections``
classes (:data:`ALLOWED_BUILTINS`) may be named; any other name (a function such as
``os.system``) refuses the file before anything in it runs. That narrows what a crafted file
can do, it does not make one safe: like the cache (:mod:`quadsim.gap.cache`), a reference
file must be one you wrote or one that came with quadsim.

**In sample.** A judged log whose bytes are one of the stored reference's own flights (the
header's SHA-256; :func:`own_flights`) is judged against references that include it: the run's
notes say so (:func:`in_sample_note`). A copy with other bytes (re-compressed, columns cut) is
not recognised.

**Staleness.** The stage is bound to the code that computed it: a quadsim that calibrates
differently would judge against an older model than ``--reference LOGS`` gives. Reading
does not compare code (the header's ``code`` is for information: any edit of any module
changes it). The rules a maintainer keeps: bump :data:`FORMAT` whenever the stored stage's
meaning changes (a field of :class:`~quadsim.gap.calibrate.Calibrated` or
:class:`~quadsim.gap.reference.Reference` added, removed or reinterpreted) -- older files are
then refused with the command that writes them again; rerun
``scripts/write_crazyflie_reference.py`` whenever the calibration's numbers change (the data
test ``tests/test_reference_file_data.py`` fails until then: the shipped file must judge the
26 mixed Crazyflie flights as a fresh calibration of the 20 nominal flights does); the CI
test ``tests/test_reference_file.py`` checks without data that the shipped file loads with
this code, that its header matches ``models/crazyflie21.toml``'s content and that a
generated flight can be judged against it.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import io
import json
import pickle
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError

__all__ = ["ALLOWED_BUILTINS", "FORMAT", "JUDGES", "SCHEMA", "SUFFIX", "Binding", "Stored",
           "binding_of", "effects_hash", "in_sample_note", "is_reference_file", "judges_of",
           "make_header", "mismatch", "model_from_json", "model_to_json", "own_flights",
           "params_hash", "read_header", "read_reference", "shipped_reference",
           "write_reference"]

#: the file's kind: another string is not a stored reference of this layout
SCHEMA = "quadsim.gap.reference/1"
#: bumped whenever the stored stage's meaning changes (module doc, "Staleness"); a file of
#: another format is refused with the command that writes it again
FORMAT = 1
#: a stored reference file's name ends in this
SUFFIX = ".qref"
#: the shipped files' folder inside ``models/``
SHIPPED_FOLDER = "references"
#: a set's shipped file for command-only logs: ``NAME`` + this + :data:`SUFFIX`
COMMANDS_TAG = "_commands"
#: the header's ``judges``: references with rotor speeds, or command-only references
JUDGES = ("speeds", "commands")
#: the pickled stage's type (the header's ``stage.type``)
STAGE_TYPE = "quadsim.gap.calibrate.Calibrated"
#: module -> names the restricted unpickler allows besides quadsim's and numpy's classes
ALLOWED_BUILTINS = {
    "builtins": {"complex", "set", "frozenset", "slice", "range", "bytearray", "bytes",
                 "tuple", "list", "dict", "int", "float", "bool", "str", "object"},
    "collections": {"OrderedDict", "defaultdict", "deque", "Counter"},
    "pathlib": {"Path", "PosixPath", "PurePosixPath", "WindowsPath", "PureWindowsPath"},
    "numpy.core.multiarray": {"_reconstruct", "scalar"},
    "numpy._core.multiarray": {"_reconstruct", "scalar"},
    "numpy.core.numeric": {"_frombuffer"},
    "numpy._core.numeric": {"_frombuffer"},
}
#: parameter-set fields that do not change the model (left out of :func:`params_hash`)
_METADATA = frozenset({"name", "description", "sources", "warnings", "path", "cad_dir",
                       "source"})


@dataclass(frozen=True)
class Binding:
    """What a stored stage is valid for: the parameter set (``model``: name, and
    ``model_sha``, :func:`params_hash`), the effects already in the model
    (``effects_file``: the file's name or None; ``effects_sha``: :func:`effects_hash` or
    None), the candidate effects (``effects``: a tuple of names or None, the whole library)
    and the smoothing window ``window_s`` (s)."""

    model: str
    model_sha: str
    effects_file: str | None
    effects_sha: str | None
    effects: tuple | None
    window_s: float


@dataclass(frozen=True)
class Stored:
    """A read stored reference: its ``path``, ``header`` (the JSON dict) and ``stage`` (a
    :class:`~quadsim.gap.calibrate.Calibrated`)."""

    path: Path
    header: dict
    stage: object

    @property
    def found(self) -> tuple:
        """The loader's warnings on the references when the file was written."""
        return tuple(self.header["loaded"]["warnings"])

    @property
    def notes(self) -> tuple:
        """The checks' notes on the references when the file was written."""
        return tuple(self.header["loaded"]["notes"])

    @property
    def samples(self) -> int:
        """The references' logged samples (counted against the cost caps)."""
        return int(self.header["loaded"]["samples"])

    @property
    def judges(self) -> str:
        """"speeds" or "commands" (module doc, "Command-only references")."""
        return judges_of(self.header)

    def command_model(self, params):
        """The stored command -> speed model (``params``: the run's parameter set, the
        file's content, for a ``motor_map`` model), or None in a "speeds" file."""
        data = self.header.get("command_model")
        return None if data is None else model_from_json(data, params, self.path)


def judges_of(header: dict) -> str:
    """A header's ``judges`` ("speeds" where absent: files written before it)."""
    return header.get("judges") or "speeds"


def _hex(values) -> list:
    return [float(x).hex() for x in np.asarray(values, dtype=float).ravel()]


def _unhex(values, path, field) -> np.ndarray:
    try:
        return np.array([float.fromhex(str(x)) for x in values], dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{path}: command_model.{field}: not a list of hex floats") from None


def model_to_json(model) -> dict:
    """A command -> speed model (:class:`~quadsim.gap.logcheck.CommandModel`,
    :class:`~quadsim.gap.logcheck.MapCommandModel` or :class:`~quadsim.gap.logcheck.
    BalancedModel` of either) as the header's ``command_model`` (floats as ``float.hex``)."""
    from .logcheck import BalancedModel, CommandModel, MapCommandModel

    if isinstance(model, BalancedModel):
        return {"type": "balanced", "factors": _hex(model.factors),
                "model": model_to_json(model.model)}
    if isinstance(model, CommandModel):
        return {"type": "fitted", "a": _hex(model.a), "b": _hex(model.b), "c": _hex(model.c),
                "v_ref": float(model.v_ref).hex(), "tau": float(model.tau).hex(),
                "rms": float(model.rms).hex(), "samples": int(model.samples),
                "source": model.source}
    if isinstance(model, MapCommandModel):
        return {"type": "motor_map", "tau": float(model.tau).hex(),
                "rms": float(model.rms).hex(), "source": model.source}
    raise TypeError(f"no stored form for a {type(model).__name__}")


def model_from_json(data, params, path="reference file"):
    """The command model of a header's ``command_model`` (:func:`model_to_json`'s inverse,
    bit for bit); ``params``: the run's parameter set (a ``motor_map`` model's map). A
    malformed one: :class:`InputError` naming the file and the field."""
    from .logcheck import BalancedModel, CommandModel, MapCommandModel

    kind = data.get("type") if isinstance(data, dict) else None
    try:
        if kind == "balanced":
            return BalancedModel(model_from_json(data["model"], params, path),
                                 _unhex(data["factors"], path, "factors"))
        if kind == "fitted":
            one = lambda k: float(_unhex([data[k]], path, k)[0])   # noqa: E731
            return CommandModel(_unhex(data["a"], path, "a"), _unhex(data["b"], path, "b"),
                                _unhex(data["c"], path, "c"), one("v_ref"), one("tau"),
                                one("rms"), int(data["samples"]), str(data["source"]))
        if kind == "motor_map":
            return MapCommandModel(params, float(_unhex([data["tau"]], path, "tau")[0]),
                                   str(data["source"]),
                                   float(_unhex([data["rms"]], path, "rms")[0]))
    except KeyError as exc:
        raise InputError(f"{path}: command_model.{exc.args[0]}: missing") from None
    raise InputError(f"{path}: command_model.type: {kind!r}, not fitted, motor_map or "
                     "balanced")


def _canonical(value):
    """``value`` (a parameter set, an effect, or a part of one) as plain JSON data whose
    text is the same exactly when the numbers are: floats as ``float.hex``, arrays as shape
    and hex floats, dataclasses field by field without :data:`_METADATA`."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _canonical(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name not in _METADATA}
    if isinstance(value, np.ndarray):
        return [list(value.shape), [float(x).hex() for x in value.ravel()]]
    if isinstance(value, (bool, str, type(None))):
        return value
    if isinstance(value, (int, float, np.floating, np.integer)):
        return float(value).hex()
    if isinstance(value, (tuple, list)):
        return [_canonical(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    return repr(value)


def params_hash(params) -> str:
    """SHA-256 (hex) of a parameter set's content: every number and choice that shapes the
    model (mass, inertia, rotors, b, d, the motor map, ...), not its name, description,
    sources or path; so a renamed copy of a set has its hash, an edited number does not."""
    text = json.dumps(_canonical(params), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def effects_hash(base) -> str | None:
    """SHA-256 (hex) of the effects already in the model (an effect file's: each one's name
    and parameter values, in order); None for none."""
    if not base:
        return None
    items = [[e.name, {p.name: float(getattr(e, p.name)).hex() for p in e.parameters}]
             for e in base]
    return hashlib.sha256(json.dumps(items, sort_keys=True).encode()).hexdigest()


def binding_of(params, *, base=(), effects_file=None, effects=None,
               window_s: float) -> Binding:
    """The :class:`Binding` of a run: ``params`` (loaded), ``base`` (the effects of
    ``effects_file``), ``effects`` (``--effects`` names or None), ``window_s`` (s)."""
    return Binding(params.name, params_hash(params),
                   None if effects_file is None else Path(effects_file).name,
                   effects_hash(tuple(base)),
                   None if effects is None else tuple(effects), float(window_s))


def _file_entry(path) -> dict:
    data = Path(path).read_bytes()
    return {"file": str(path), "bytes": len(data),
            "sha256": hashlib.sha256(data).hexdigest()}


@dataclass(frozen=True)
class Provenance:
    """Where a stage comes from, for the header: ``references`` and ``command_references``
    (paths), ``source`` (free text), ``command`` (argv), ``loaded`` ({"samples",
    "warnings", "notes"})."""

    references: tuple
    command_references: tuple = ()
    source: str = ""
    command: tuple = ()
    loaded: dict = dataclasses.field(default_factory=dict)


def make_header(binding: Binding, stage, provenance: Provenance, payload: bytes,
                command_model=None) -> dict:
    """The JSON header (module doc, "File format") of ``stage`` pickled as ``payload``;
    ``command_model``: the model that synthesised command-only references' speeds (a
    "commands" file), or None (a "speeds" file)."""
    from .. import __version__
    from .calibrate import code_version

    written = datetime.datetime.now(datetime.UTC).replace(microsecond=0)
    return {
        "schema": SCHEMA, "format": FORMAT, "quadsim": __version__, "code": code_version(),
        "written": written.isoformat(), "command": shlex.join(provenance.command),
        "source": provenance.source,
        "model": {"name": binding.model, "sha256": binding.model_sha},
        "effects_file": (None if binding.effects_sha is None else
                         {"name": binding.effects_file, "sha256": binding.effects_sha}),
        "effects": None if binding.effects is None else list(binding.effects),
        "window_s": binding.window_s,
        "references": [_file_entry(p) for p in provenance.references],
        "command_references": [_file_entry(p) for p in provenance.command_references],
        "count": int(stage.count),
        "loaded": {"samples": int(provenance.loaded.get("samples", 0)),
                   "warnings": list(provenance.loaded.get("warnings", ())),
                   "notes": list(provenance.loaded.get("notes", ()))},
        "judges": JUDGES[command_model is not None],
        "command_model": None if command_model is None else model_to_json(command_model),
        "stage": {"type": STAGE_TYPE, "encoding": "pickle/4", "bytes": len(payload),
                  "sha256": hashlib.sha256(payload).hexdigest()},
    }


def with_paths(stage, path=None, cad_dir=None):
    """``stage`` with its reference model's parameter set naming ``path`` and ``cad_dir``
    (nothing else changed; only messages read them): written with the file's bare name and
    no CAD folder (no machine's folders in a shipped file), read back with the run's."""
    import copy

    ref = copy.copy(stage.reference)
    ref.params = dataclasses.replace(ref.params, path=path, cad_dir=cad_dir)
    return dataclasses.replace(stage, reference=ref)


def write_reference(path, binding: Binding, stage, provenance: Provenance,
                    command_model=None) -> Path:
    """Write ``stage`` (a :class:`~quadsim.gap.calibrate.Calibrated`) to ``path`` (ending in
    :data:`SUFFIX`) atomically, with ``command_model`` where the references were
    command-only (module doc, "Command-only references"): a temporary file renamed into
    place (its parameter set
    naming only its file's name, :func:`with_paths`; no cache key): the same references,
    model and options give the same stage values, bit for bit (the bytes too within one
    process; across processes a dict's key order may follow Python's string hashing).
    -> the path."""
    from ..core.files import atomic_write_bytes

    own = stage.reference.params.path
    stage = dataclasses.replace(with_paths(stage, None if own is None else Path(Path(own).name)),
                                key="")       # the cache's key: no meaning in a file
    payload = pickle.dumps(stage, protocol=4)
    header = make_header(binding, stage, provenance, payload, command_model)
    line = json.dumps(header, separators=(", ", ": ")).encode("utf-8") + b"\n"
    return atomic_write_bytes(path, line + payload)


def is_reference_file(path) -> bool:
    """True when ``path``'s name ends in :data:`SUFFIX`."""
    return str(path).endswith(SUFFIX)


def _split(path: Path) -> tuple[dict, bytes]:
    """(header, the bytes after it) of ``path``; a foreign file: :class:`InputError`."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    line, newline, payload = data.partition(b"\n")
    try:
        header = json.loads(line.decode("utf-8")) if newline else None
    except (UnicodeDecodeError, ValueError):
        header = None
    if not isinstance(header, dict) or "schema" not in header:
        raise InputError(f"{path}: header: not a quadsim stored reference (its first line is "
                         f"not the JSON header of {SCHEMA})")
    return header, payload


def _again(header: dict) -> str:
    command = header.get("command") or ("python -m quadsim.gap --model MODEL --reference "
                                        "LOGS... --write-reference OUT.qref")
    return f"write it again with `{command}`"


_FIELDS = {"model": dict, "effects_file": (dict, type(None)), "effects": (list, type(None)),
           "window_s": (int, float), "references": list, "count": int, "loaded": dict,
           "stage": dict, "command": str}


def read_header(path) -> dict:
    """The header of the stored reference ``path``, checked (schema, format, the fields'
    types) without unpickling anything; a refusal: :class:`InputError` (one line)."""
    path = Path(path)
    header, _ = _split(path)
    if header["schema"] != SCHEMA:
        raise InputError(f"{path}: schema: {header['schema']!r}, this quadsim reads {SCHEMA!r}")
    if header.get("format") != FORMAT:
        raise InputError(f"{path}: format: written by format {header.get('format')!r}, this "
                         f"quadsim reads {FORMAT}: {_again(header)}")
    for key, kind in _FIELDS.items():
        if not isinstance(header.get(key), kind):
            raise InputError(f"{path}: {key}: missing or of the wrong type in the header")
    if header.get("judges", "speeds") not in JUDGES:
        raise InputError(f"{path}: judges: {header.get('judges')!r}, not one of {JUDGES}")
    if not isinstance(header.get("command_model"), (dict, type(None))):
        raise InputError(f"{path}: command_model: of the wrong type in the header")
    if (judges_of(header) == "commands") != (header.get("command_model") is not None):
        raise InputError(f"{path}: command_model: a \"commands\" file holds one, a "
                         "\"speeds\" file none")
    return header


class _Restricted(pickle.Unpickler):
    """An unpickler that resolves only quadsim's dataclasses (their constructors only set
    fields), numpy's ``ndarray``, ``dtype`` and scalar types (not ``memmap``, whose
    constructor opens a file), and the names of :data:`ALLOWED_BUILTINS`; anything else
    raises ``pickle.UnpicklingError`` before it is called."""

    def find_class(self, module: str, name: str):
        if name in ALLOWED_BUILTINS.get(module, ()):
            return super().find_class(module, name)
        root = module.split(".")[0]
        if root in ("quadsim", "numpy"):
            found = super().find_class(module, name)
            if root == "quadsim" and isinstance(found, type) and dataclasses.is_dataclass(found):
                return found
            if root == "numpy" and (found is np.ndarray or found is np.dtype or (
                    isinstance(found, type) and issubclass(found, np.generic))):
                return found
        raise pickle.UnpicklingError(f"{module}.{name}")


def read_reference(path) -> Stored:
    """The stored reference ``path``: its header checked (:func:`read_header`), its stage's
    length and SHA-256 checked against the header, then unpickled by :class:`_Restricted`.
    Any refusal: :class:`InputError` (one line naming the file and the field)."""
    from .calibrate import Calibrated

    path = Path(path)
    header = read_header(path)
    _, payload = _split(path)
    want = header["stage"]
    if len(payload) != want.get("bytes"):
        raise InputError(f"{path}: stage: {len(payload)} bytes where the header says "
                         f"{want.get('bytes')} (truncated or altered): {_again(header)}")
    if hashlib.sha256(payload).hexdigest() != want.get("sha256"):
        raise InputError(f"{path}: stage: its SHA-256 is not the header's (altered): "
                         f"{_again(header)}")
    try:
        stage = _Restricted(io.BytesIO(payload)).load()
    except pickle.UnpicklingError as exc:
        raise InputError(f"{path}: stage: names {exc}, outside what a stored reference may "
                         "hold (quadsim and numpy classes, a few builtins): refused, nothing "
                         "in it run") from None
    except Exception as exc:   # a class this code lacks, another numpy, ...
        raise InputError(f"{path}: stage: cannot be read by this quadsim "
                         f"({type(exc).__name__}: {exc}): {_again(header)}") from None
    if not isinstance(stage, Calibrated):
        raise InputError(f"{path}: stage: a {type(stage).__name__}, not a {STAGE_TYPE}")
    return Stored(path, header, stage)


def _effects_text(effects) -> str:
    return "the whole library" if effects is None else "--effects " + " ".join(effects)


def mismatch(header: dict, binding: Binding) -> str | None:
    """The first field in which the stored stage (``header``) does not fit the run
    (``binding``), as "field: calibrated ..., this run's ..."; None when it fits."""
    model = header["model"]
    if model.get("sha256") != binding.model_sha:
        return (f"model: calibrated for {model.get('name')} (sha256 "
                f"{str(model.get('sha256'))[:12]}), this run's model is {binding.model} "
                f"(sha256 {binding.model_sha[:12]})")
    stored = header["effects_file"]
    if (None if stored is None else stored.get("sha256")) != binding.effects_sha:
        were = "none" if stored is None else f"{stored.get('name')} ({stored['sha256'][:12]})"
        now = ("none" if binding.effects_sha is None else
               f"{binding.effects_file} ({binding.effects_sha[:12]})")
        return (f"effects_file: calibrated on top of the effects of {were}, this run's "
                f"--effects-file: {now}")
    effects = None if header["effects"] is None else tuple(header["effects"])
    if effects != binding.effects:
        return (f"effects: calibrated for {_effects_text(effects)}, this run's "
                f"{_effects_text(binding.effects)}")
    if float(header["window_s"]) != binding.window_s:
        return (f"window_s: calibrated with --window {header['window_s']:g} s, this run's "
                f"is {binding.window_s:g} s")
    return None


def check_fits(path, header: dict, binding: Binding) -> None:
    """Refuse (one line) a stored reference that does not fit the run (:func:`mismatch`)."""
    wrong = mismatch(header, binding)
    if wrong is not None:
        raise InputError(f"{path}: {wrong}: give the --model/--effects-file/--effects/"
                         f"--window it was written with, or write one for this run "
                         "(--reference LOGS... --write-reference OUT.qref)")


def own_flights(header: dict, paths) -> list[tuple[str, str]]:
    """(given path, the header's file name) of each of ``paths`` whose bytes are one of the
    stored reference's own flights (the same SHA-256 as a ``references`` or
    ``command_references`` entry): a flight judged against references that include it. A
    copy whose bytes differ (re-compressed, columns cut) is not found."""
    known = {entry["sha256"]: entry["file"]
             for entry in [*header.get("references", ()), *header.get("command_references", ())]
             if isinstance(entry, dict) and "sha256" in entry}
    out = []
    for path in paths:
        try:
            digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        except OSError:
            continue
        if digest in known:
            out.append((str(path), known[digest]))
    return out


def in_sample_note(header: dict, paths) -> str | None:
    """The note for :func:`own_flights` of ``paths``, or None when there are none."""
    found = own_flights(header, paths)
    if not found:
        return None
    named = ", ".join(f"{given} (its {own})" if Path(given).name != Path(own).name else given
                      for given, own in found)
    return (f"judged in sample: {named} {'is' if len(found) == 1 else 'are'} among the stored "
            f"reference's own {header.get('count', '?')} flights (the same bytes): a flight is "
            "judged against references that include it, so its answer shows less difference "
            "than a new flight's would")


def shipped_reference(name: str, commands: bool = False) -> Path | None:
    """The shipped reference file of the built-in parameter set ``name``
    (``models/references/NAME.qref``; ``commands``: ``NAME_commands.qref``, for command-only
    logs; module doc), or None when it ships none."""
    from ..core.shipped import shipped_dir

    tag = COMMANDS_TAG if commands else ""
    path = shipped_dir("models") / SHIPPED_FOLDER / f"{name}{tag}{SUFFIX}"
    return path if path.is_file() else None


def describe(stored: Stored, shipped: bool) -> dict:
    """The JSON ``reference_file`` of a run judged against ``stored``: its file name,
    whether it is the set's shipped one, schema, format, when and from what it was written,
    its source, the reference count and the references' names."""
    h = stored.header
    return {"file": stored.path.name, "shipped": bool(shipped), "schema": h["schema"],
            "format": h["format"], "judges": judges_of(h), "written": h.get("written"),
            "source": h.get("source", ""),
            "count": h["count"], "references": [r["file"] for r in h["references"]],
            "model": h["model"]}


def sentence(stored: Stored, shipped: bool) -> str:
    """The answer's sentence naming what the flights were judged against ("Judged against
    the set's own 20 nominal flights (shipped reference crazyflie21.qref, written
    2026-11-29).")."""
    h = stored.header
    what = "the set's own" if shipped else "the"
    kind = ", commands only" if judges_of(h) == "commands" else ""
    return (f"Judged against {what} {h['count']} nominal flights{kind} "
            f"({'shipped' if shipped else 'stored'} reference {stored.path.name}, written "
            f"{str(h.get('written', '?'))[:10]}).")


if __name__ == "__main__":    # pragma: no cover - `python -m quadsim.gap.reffile FILE`
    for arg in sys.argv[1:]:
        print(json.dumps(read_header(arg), indent=2))
