"""dhct: drift, hysteresis and creep correction (DHCT) of atomically resolved STM images.

Numpy arrays in and out; lengths in metres, times in seconds. The work runs in Rust with
the GIL released, so threads (or a Dask/Ray worker pool) can correct several scans at once.

>>> import dhct
>>> scan = dhct.read("tests/data/simulated_graphite.sm4")
>>> result = dhct.correct(scan)             # the graphite lattice by default
>>> result.corrected_trace.shape == scan.shape
True

Options are resolved exactly as ``dhct correct`` resolves its flags (the same lattice
presets, ``nn``, the same checks of the inputs against the image, the same config file
merging), and :meth:`Result.write` writes the same files. Errors raise
:class:`DhctError` subclasses carrying the command line's messages.
"""

from __future__ import annotations

import difflib
import html
import json
import os
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _dhct
from ._dhct import (
    AnalysisError,
    DhctError,
    InputMismatchError,
    OptionError,
    ReadError,
    Scan,
    SimulationError,
    WriteError,
    __version__,
)

__all__ = [
    "AnalysisError",
    "DhctError",
    "InputMismatchError",
    "OptionError",
    "ReadError",
    "Result",
    "Scan",
    "Simulation",
    "SimulationError",
    "WriteError",
    "__version__",
    "correct",
    "correct_series",
    "diagnose",
    "lattices",
    "map_points",
    "presets",
    "read",
    "simulate",
    "simulate_sequence",
]

PathLike = Union[str, "os.PathLike[str]"]

#: Geometry options (replacing what the file says): name -> (config key(s), unit).
_GEOMETRY = {
    "pitch": ("pitch_x", "pitch_y"),
    "pixel_period": ("pixel_period",),
    "line_time": ("line_time",),
    "turnaround": ("turnaround_time",),
    "fast": ("trace_fast",),
    "slow": ("slow",),
}

#: `correct` options that are config keys of the same name.
_PLAIN = (
    "polarity",
    "plane_group",
    "colormap",
    "mask_polygon",
    "displacement",
    "channels",
    "extent",
)

_OPTIONS = (
    ("retrace", "config", "calibrate", "trust_inputs", "pipeline", "progress")
    + _PLAIN
    + tuple(_GEOMETRY)
)


def _check_names(given: Mapping[str, Any], valid: Sequence[str]) -> None:
    """Raises OptionError naming an unknown option and the closest valid one."""
    for name in given:
        if name not in valid:
            close = difflib.get_close_matches(name, valid, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise OptionError(
                f"unknown option {name!r}{hint} (valid: {', '.join(sorted(valid))})"
            )


def _geometry(options: Mapping[str, Any]) -> Dict[str, Any]:
    """The geometry overrides of ``options`` as config keys (metres, seconds)."""
    geometry: Dict[str, Any] = {}
    for name, keys in _GEOMETRY.items():
        value = options.get(name)
        if value is None:
            continue
        if name == "pitch" and not isinstance(value, (int, float)):
            pitch = tuple(float(v) for v in value)
            if len(pitch) != 2:
                raise OptionError("pitch must be a number or a pair (x, y), metres")
            geometry.update(pitch_x=pitch[0], pitch_y=pitch[1])
            continue
        for key in keys:
            geometry[key] = value if isinstance(value, str) else float(value)
    return geometry


def _without_none(value: Any) -> Any:
    """``value`` with None entries of nested dicts dropped (TOML has no null)."""
    if isinstance(value, Mapping):
        return {str(k): _without_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_without_none(v) for v in value]
    return value


def read(
    path: PathLike,
    channel: Optional[str] = None,
    *,
    pitch: Union[float, Tuple[float, float], None] = None,
    pixel_period: Optional[float] = None,
    line_time: Optional[float] = None,
    turnaround: Optional[float] = None,
    fast: Optional[str] = None,
    slow: Optional[str] = None,
) -> Scan:
    """Reads a scan file (RHK SM4, Nanonis SXM, ISO 28600, GSF, NPY, TIFF, Createc DAT,
    Omicron MATRIX with its parameter file beside it, WSxM; detected from content).

    ``channel`` picks a channel by name (case-insensitive, whole name first, then a part
    of it); by default the topography. The geometry options replace what the file says:
    ``pitch`` in metres (one value or (x, y)), ``pixel_period``, ``line_time`` and
    ``turnaround`` in seconds, ``fast``/``slow`` directions (right, left, up, down).

    Raises ReadError when the file cannot be read or holds no such channel, OptionError
    for an implausible geometry value.
    """
    geometry = _geometry(
        dict(
            pitch=pitch,
            pixel_period=pixel_period,
            line_time=line_time,
            turnaround=turnaround,
            fast=fast,
            slow=slow,
        )
    )
    overrides = json.dumps(geometry) if geometry else None
    return _dhct.read(os.fspath(path), channel, overrides)


def _config_options(lattice: Optional[str], nn: Any, options: Mapping[str, Any]) -> Dict[str, Any]:
    """The options of ``correct`` as ``dhct correct`` config keys."""
    config: Dict[str, Any] = {}
    if lattice is not None:
        config["lattice"] = os.fspath(lattice)
    if nn is not None:
        config["nn"] = nn if isinstance(nn, str) else float(nn)
    for flag in ("calibrate", "trust_inputs"):
        if options.get(flag):
            config[flag] = True
    for key in _PLAIN:
        if options.get(key) is not None:
            config[key] = options[key]
    if options.get("mask_polygon") is not None:
        config["mask_polygon"] = [[float(x), float(y)] for x, y in options["mask_polygon"]]
    if options.get("pipeline") is not None:
        config["pipeline"] = _without_none(options["pipeline"])
    geometry = _geometry(options)
    if geometry:
        config["geometry"] = geometry
    return config


def correct(
    scan_or_path: Union[Scan, PathLike],
    lattice: Optional[str] = None,
    nn: Union[float, str, None] = None,
    mask: Union[PathLike, np.ndarray, None] = None,
    **options: Any,
) -> "Result":
    """Corrects drift, creep and hysteresis in a scan and analyses its lattice.

    ``scan_or_path``: a :class:`Scan` or the path of a scan file. ``lattice``: a name of
    the lattice catalogue (see :func:`lattices`: graphite, the default, honeycomb,
    hexagonal, sam-sqrt3, si111-7x7, square, rectangular, centred-rectangular, oblique,
    kagome) or a lattice file (TOML/JSON). ``nn``: the nearest-neighbour distance in metres (a float), as text with
    a unit ("2.46A", "0.246nm"), or "auto" (the distance the image shows); presets with a
    known constant need none. ``mask``: a mask file (PNG, NPY, TIFF) or a 2-D array of the
    scan's shape (non-zero = analyse).

    Options (keyword only; as ``dhct correct``'s flags and config keys):
    ``retrace`` (a second file holding the retrace, with a path input), ``config`` (a TOML
    config such as a written config.toml; the options given replace its values),
    ``calibrate``, ``trust_inputs``, ``polarity`` ("bright"/"dark"), ``plane_group``
    ("p3m1", ...), ``colormap``, ``displacement`` (True: :meth:`Result.write` also writes
    each pass's displacement field), ``channels`` ("all": :meth:`Result.write` also writes
    every other channel of the file, corrected with the same model), ``extent`` ("full":
    :meth:`Result.write` writes the corrected TIFF/GSF with every corrected pixel), ``mask_polygon`` ([(x, y), ...] pixels), ``pipeline`` (a
    dict shaped like the config's [pipeline] table, e.g.
    ``{"features": {"min_relative_height": 0.5}}``), the geometry ``pitch`` (metres),
    ``pixel_period``, ``line_time``, ``turnaround`` (seconds), ``fast``, ``slow``, and
    ``progress`` (a callable given each stage's description, or True for a tqdm bar).

    Raises OptionError (an invalid option, config or mask), ReadError, InputMismatchError
    (the image does not show the lattice or constant given; the message names the option
    to change), AnalysisError.
    """
    _check_names(options, _OPTIONS)
    config = _config_options(lattice, nn, options)
    mask_array = None
    if isinstance(mask, np.ndarray):
        if mask.ndim != 2:
            raise OptionError(f"mask must be a 2-D array, not {mask.ndim}-D")
        mask_array = np.ascontiguousarray(mask != 0)
    elif mask is not None:
        config["mask"] = os.fspath(mask)
    if isinstance(scan_or_path, Scan):
        source: Union[Scan, str] = scan_or_path
    elif isinstance(scan_or_path, (str, os.PathLike)):
        source = os.fspath(scan_or_path)
    else:
        raise OptionError(
            f"the input must be a dhct.Scan or a path, not {type(scan_or_path).__name__}"
        )
    retrace = options.get("retrace")
    config_path = options.get("config")
    progress, done = _progress(options.get("progress"))
    try:
        raw = _dhct.correct(
            source,
            json.dumps(config),
            os.fspath(config_path) if config_path is not None else None,
            os.fspath(retrace) if retrace is not None else None,
            mask_array,
            progress,
        )
    finally:
        done()
    return Result(raw)


def _progress(progress: Any) -> Tuple[Optional[Callable[[str], Any]], Callable[[], None]]:
    """The stage callback and what to call at the end: ``progress=True`` shows a tqdm bar
    when tqdm is installed (else one line per stage on stderr); a callable is called with
    each stage's description; None or False shows nothing."""
    if progress is None or progress is False:
        return None, lambda: None
    if callable(progress):
        return progress, lambda: None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        import sys

        return (lambda stage: print(f"dhct: {stage}", file=sys.stderr)), lambda: None
    bar = tqdm(desc="dhct", unit="stage")

    def update(stage: str) -> None:
        bar.set_postfix_str(stage)
        bar.update()

    return update, bar.close


class Result:
    """What :func:`correct` found: corrected images, features, the fitted model (the content
    of model.json), the lattice fits and the unit cell. Lengths in metres, times in
    seconds."""

    def __init__(self, raw: "_dhct.Correction") -> None:
        self._raw = raw
        self._model: Optional[Dict[str, Any]] = None
        self._features: Optional[Dict[str, np.ndarray]] = None

    @property
    def corrected_trace(self) -> Optional[np.ndarray]:
        """The corrected trace image (float64, the scan's shape, NaN where no data)."""
        return self._raw.corrected("trace")

    @property
    def corrected_retrace(self) -> Optional[np.ndarray]:
        """The corrected retrace image (float64, the scan's shape), or None."""
        return self._raw.corrected("retrace")

    @property
    def scan(self) -> Scan:
        """The scan that was analysed (with any geometry options applied)."""
        return self._raw.scan()

    @property
    def features(self) -> Dict[str, np.ndarray]:
        """Every feature of every pass as equal-length numpy columns (the columns of
        features.csv): fitted position (``x_px``, ``y_px``; ``x_m``, ``y_m`` metres), widths,
        height, fit quality, acquisition time (``time_s``, ``line_time_s``), corrected
        position (``corrected_x_m``, ``corrected_y_m``), ``indexed`` and, where indexed,
        ``region``, ``n``, ``m``, ``site`` (-1 where not) and the deviation from the fitted
        site (``deviation_x_m``, ``deviation_y_m``; NaN where not)."""
        if self._features is None:
            columns = self._raw.feature_columns()
            self._features = {
                name: np.asarray(values, dtype=str) if isinstance(values, list) else values
                for name, values in columns.items()
            }
        return dict(self._features)

    def features_frame(self) -> Any:
        """The features as a pandas DataFrame (needs pandas)."""
        try:
            import pandas as pd
        except ImportError as error:  # pragma: no cover - depends on the environment
            raise ImportError(
                "features_frame() needs pandas (pip install pandas); .features holds the "
                "same columns as numpy arrays"
            ) from error
        return pd.DataFrame(self.features)

    @property
    def model(self) -> Dict[str, Any]:
        """The fitted model: the content of model.json (parameters with value, sigma, unit
        and whether the data determine them; goodness of fit; counts; lattice fits;
        ellipses; warnings; calibration; timings)."""
        if self._model is None:
            self._model = json.loads(self._raw.model_json())
        return self._model

    @property
    def parameters(self) -> Dict[str, Dict[str, Any]]:
        """The model parameters by name: value, sigma (None when undetermined), unit."""
        return {p["name"]: p for p in self.model["parameters"]}

    @property
    def warnings(self) -> List[Dict[str, str]]:
        """What not to trust and what to do: each ``{"code", "message", "what_to_do"}``,
        with ``"inputs"`` (the keyword arguments the advice refers to, by quantity, e.g.
        ``"mask"``, ``"nearest_neighbour_distance"``) and ``"suggests_diagnosis": True``
        (the advice is :func:`diagnose`) where they apply."""
        return list(self.model["warnings"])

    @property
    def calibration(self) -> Optional[Dict[str, Any]]:
        """The lattice each image shows in file units and the calibration it gives (x and y
        scale, shear, rotation), or None when it could not be measured."""
        return self.model["calibration"]

    @property
    def lattice(self) -> Dict[str, Any]:
        """The lattice given (name, nearest-neighbour distance, primitive vectors as a 2 x 2
        array in metres, plane group) and one fit per mask region (``regions``: lattice
        constants, angle, rms deviation, ...)."""
        given = self._raw.lattice_given()
        given["regions"] = self.model["regions"]
        return given

    @property
    def unit_cell(self) -> Optional[Dict[str, Any]]:
        """The averaged and symmetry-averaged unit cell (``averaged``, ``symmetrized``:
        float64 arrays on the fractional grid), the plane group and cell counts; None when
        no cell was averaged (``model["unit_cell_note"]`` says why)."""
        return self._raw.unit_cell()

    def diagnose(self) -> Dict[str, Any]:
        """The sim-to-real gap diagnosis of this run's features: where the fitted model and
        the image disagree (in time, fast-line phase, space, trace vs retrace), which
        unmodelled effect explains it, and the verdict; the content of the diagnosis.json
        that ``dhct correct --diagnose`` writes."""
        return json.loads(self._raw.diagnose_json())

    def write(self, outdir: PathLike, overwrite: bool = False, diagnose: bool = False) -> Dict[str, Any]:
        """Writes the same files as ``dhct correct ... -o outdir`` (report.html, corrected
        images, features.csv, model.json, config.toml, figures); an earlier run's folder is
        replaced only with ``overwrite``, a folder of other files never. Returns the model
        as written (``outputs`` lists the files). Raises WriteError."""
        return json.loads(self._raw.write(os.fspath(outdir), overwrite, diagnose))

    def __repr__(self) -> str:
        passes = ", ".join(f"{p['pass']} {p['features']}" for p in self.model["passes"])
        return (
            f"<dhct.Result {self.model['lattice']}: features {passes}; "
            f"{len(self.model['parameters'])} parameters, {len(self.warnings)} warnings>"
        )

    def _repr_html_(self) -> str:
        """A notebook summary: counts, parameters with 1-sigma uncertainties, warnings."""
        e = html.escape
        rows = []
        for p in self.model["parameters"]:
            sigma = "undetermined" if p["sigma"] is None else f"{p['sigma']:.4g}"
            rows.append(
                f"<tr><td>{e(p['name'])}</td><td>{p['value']:.6g}</td>"
                f"<td>{e(sigma)}</td><td>{e(p['unit'])}</td></tr>"
            )
        warnings = "".join(
            f"<li><b>{e(w['code'])}</b>: {e(w['message'])}</li>" for w in self.warnings
        )
        passes = ", ".join(
            f"{e(p['pass'])}: {p['features']} features ({p['indexed']} indexed)"
            for p in self.model["passes"]
        )
        return (
            f"<div><b>dhct</b> {e(self.model['lattice'])} &mdash; {passes}"
            f"<table><tr><th>parameter</th><th>value</th><th>&sigma;</th><th>unit</th></tr>"
            f"{''.join(rows)}</table>"
            + (f"<p>warnings:</p><ul>{warnings}</ul>" if warnings else "")
            + "</div>"
        )


def map_points(
    model: Union["Result", PathLike],
    x: Any,
    y: Any,
    t: Any = None,
    pass_: str = "trace",
    unit: str = "px",
) -> Dict[str, np.ndarray]:
    """Moves points of the frame a model was fitted on (spectroscopy positions, a grid's
    points) into its sample frame, with their 1σ.

    ``model`` is a :class:`Result` or the path of a ``model.json`` that ``dhct correct``
    wrote. ``x``, ``y``: the points in the file's display orientation, in pixels (0 at the
    first pixel's centre; ``unit="px"``) or metres from that centre (``unit="m"``). ``t``:
    when each was recorded, seconds since the frame start (NaN or omitted: when the pixel
    under it was). ``pass_``: ``"trace"`` or ``"retrace"``, the lines the tip reached them
    along. Returns numpy arrays ``corrected_x_m``, ``corrected_y_m`` (the frame of the
    features' ``corrected_*``), ``sigma_x_m``, ``sigma_y_m`` (the model's statistical 1σ;
    NaN when unknown) and ``time_s``. A point off the frame raises :class:`OptionError`.
    """
    if unit not in ("px", "m"):
        raise OptionError(f"unit={unit!r}: use 'px' or 'm'")
    if isinstance(model, Result):
        text = model._raw.model_json()
    else:
        with open(model, encoding="utf-8") as f:
            text = f.read()
    as_array = lambda v: np.ascontiguousarray(np.atleast_1d(np.asarray(v, dtype=np.float64)))
    return _dhct.map_points(
        text,
        as_array(x),
        as_array(y),
        None if t is None else as_array(t),
        pass_,
        unit == "m",
    )


def diagnose(
    scan_or_path: Union[Scan, PathLike],
    lattice: Optional[str] = None,
    nn: Union[float, str, None] = None,
    mask: Union[PathLike, np.ndarray, None] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Corrects the scan as :func:`correct` does (same arguments) and diagnoses the
    sim-to-real gap: the content of diagnosis.json from ``dhct correct --diagnose``."""
    return correct(scan_or_path, lattice, nn, mask, **options).diagnose()


@dataclass(frozen=True)
class Simulation:
    """A simulated acquisition: the scan (trace and retrace, metres), the ground truth (the
    content of ground_truth.json) and the config that made it (TOML text)."""

    scan: Scan
    truth: Dict[str, Any]
    config: str


def lattices() -> Dict[str, Dict[str, Any]]:
    """The lattice catalogue (docs/lattices.md): name -> {"aliases", "summary",
    "known_constant"}; ``correct(lattice=name)`` takes any of these names or aliases (an
    entry without a known constant needs ``nn``)."""
    return {
        name: {"aliases": list(aliases), "summary": summary, "known_constant": known}
        for name, aliases, summary, known in _dhct.lattices()
    }


def presets() -> Dict[str, str]:
    """The simulator's built-in presets: name -> one-line summary."""
    return dict(_dhct.presets())


def simulate(preset_or_config: Union[str, PathLike, Mapping[str, Any]], seed: Optional[int] = None) -> Simulation:
    """Simulates an STM acquisition with drift, creep, hysteresis and other distortions.

    ``preset_or_config``: a preset name (see :func:`presets`), the path of a TOML or JSON
    simulation config (see docs/simulator.md), or such a config as a dict. ``seed``
    replaces the config's random seed. Raises SimulationError.
    """
    if isinstance(preset_or_config, Mapping):
        args = (None, None, json.dumps(_without_none(preset_or_config)))
    elif isinstance(preset_or_config, str) and preset_or_config in presets():
        args = (preset_or_config, None, None)
    else:
        path = os.fspath(preset_or_config)
        if not os.path.exists(path):
            raise SimulationError(
                f"{path!r} is neither a preset ({', '.join(presets())}) nor a config file"
            )
        args = (None, path, None)
    scan, truth, config = _dhct.simulate(*args, seed)
    return Simulation(scan=scan, truth=json.loads(truth), config=config)



def correct_series(
    frames: Union[PathLike, Sequence[PathLike]],
    outdir: PathLike,
    lattice: Optional[str] = None,
    nn: Union[float, str, None] = None,
    knots: Optional[int] = None,
    register: str = "lattice",
    **options: Any,
) -> Dict[str, Any]:
    """Fits one model to frames of one area taken one after another and registers them
    into one sample frame, as ``dhct series`` does; writes its outputs into ``outdir``
    (series.json, features.csv, trajectory.csv, registered/) and returns series.json's
    content as a dict. Its ``warnings`` (registered images whose lattice, measured by FFT,
    is off; frames the session's model does not explain) and each frame's ``warnings``
    (its pixel size calibrated, its timing assumed) say what not to trust.

    ``frames``: files, folders or glob patterns (a path or a list of them), ordered by the
    start time each file records. ``lattice``, ``nn`` and the options are those of
    :func:`correct` (every frame is first analysed alone with them). ``knots``: interior
    knots of the drift spline over the session (default: chosen by cross-validation).
    ``register="image"``: frames without a resolved lattice, placed by what their images
    share under the same smooth drift (``series.json`` then has ``"registration": "image"``
    and lists what stays ``undetermined``: scale, hysteresis).

    Raises OptionError, AnalysisError (e.g. fewer than two frames, frames of different
    sizes, frames overlapping in time, a frame that cannot be analysed alone, frames whose
    images share nothing).
    """
    if register not in ("lattice", "image"):
        raise OptionError(f"register must be 'lattice' or 'image', not {register!r}")
    _check_names(options, tuple(name for name in _OPTIONS if name not in ("retrace", "progress")))
    config = _config_options(lattice, nn, options)
    if isinstance(frames, (str, os.PathLike)):
        frames = [frames]
    inputs = [os.fspath(f) for f in frames]
    config_path = options.get("config")
    raw = _dhct.correct_series(
        inputs,
        os.fspath(outdir),
        json.dumps(config),
        os.fspath(config_path) if config_path is not None else None,
        knots,
        register == "image",
    )
    return json.loads(raw)


def simulate_sequence(preset_or_config: Union[str, PathLike], outdir: PathLike, seed: Optional[int] = None) -> List[str]:
    """Simulates an image sequence (a preset such as ``"graphite-sequence"`` or a config
    file with a ``[sequence]`` table, see docs/simulator.md) into ``outdir``, one frame at a
    time: ``frame_NN.sm4`` and ``sequence_truth.json``. Returns the paths written. Raises
    SimulationError."""
    if isinstance(preset_or_config, str) and preset_or_config in presets():
        return list(_dhct.simulate_sequence(os.fspath(outdir), preset_or_config, None, seed))
    path = os.fspath(preset_or_config)
    if not os.path.exists(path):
        raise SimulationError(f"{path!r} is neither a preset ({', '.join(presets())}) nor a config file")
    return list(_dhct.simulate_sequence(os.fspath(outdir), None, path, seed))
