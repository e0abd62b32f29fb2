"""The library of candidate effects and their linearised evaluation (sim-to-real diagnosis).

Every candidate effect of issue 6 is one set of model terms or parameters with its own prior,
declared as data in ``models/effects/library.toml`` (:func:`load_library`) and applied on top
of the user's model.  The diagnosis evaluates all of them from **one** fit of the user's model:

1. the user's model is fitted (MAP of the Bayesian model: coefficients, each run's initial
   speed and noise ``sigma_mps``, the integrated-noise intensity ``q_mps_per_sqrt_s``);
2. a *super-model* -- the user's terms plus every candidate's terms, each candidate parameter
   at its null (no effect) -- reproduces the user's fit exactly; its speed traces are
   differentiated once (forward mode) with respect to the user's free coefficients, every
   candidate parameter and each run's initial speed (:func:`linearise`);
3. with the residual covariance of the fit (white noise + integrated noise, the exact banded
   form of :mod:`bayes_roadload.physics.residuals`) the log likelihood is quadratic in a small
   step of those parameters, so the best gain of any candidate (or set of candidates) --
   coefficients and initial speeds re-fitted with it -- is a linear solve
   (:func:`evaluate`): the likelihood-ratio statistic of a Gauss-Newton step, i.e. Rao's score
   test.  Priors of the candidate parameters enter as a ridge.

The gain in expected log predictive density is estimated as the gain in maximised log
likelihood minus the number of added parameters (Akaike's estimate of elpd; ``delta_elpd``).
Leave-one-pair-out predictive densities come from the same quadratic form (:func:`lopo_lpd`).

A candidate may be a *family*: shape parameters of its terms (a time constant, an exponent)
declared with a grid (``shape`` in the library) are not held at one value but profiled over
their grid (:func:`fit_shapes`), the grid points carrying equal prior mass (log-uniform or
uniform over the stated range), and each shape parameter is charged as one more added parameter.

Identifiability (:func:`evaluate`): for each candidate parameter, the fraction of its
information that survives re-fitting the user's coefficients, ``1 - R^2`` of its signature on
theirs (``information_ratio``), and how much the data contract its prior (``contraction``).  A
candidate whose signature the coefficients can mimic (an effective-mass error with A_D, B_D,
C_D0 free; lift unloading against C_D0; an airspeed scale against C_D0) is reported "not
identifiable here, needs X" (the library's ``needs``) instead of being claimed.  The airspeed
scale is then judged from the paired runs' kinematics (thesis 4.7.3,
:func:`airspeed_kinematics`).
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .. import config
from ..inference.spec import MODELS_DIR
from ..physics.effects import OffsetAir
from ..physics.integrate import integrate_batch
from ..physics.model import DragModel, MeasuredAir
from ..physics.residuals import _effect_terms, local_level_loglik_batch
from ..physics.terms import TERMS

_effect_terms_jit = jax.jit(_effect_terms)
_loglik_batch_jit = jax.jit(local_level_loglik_batch)

LIBRARY_PATH = MODELS_DIR / "effects" / "library.toml"
"""The candidate library shipped with the package (``models/effects/library.toml``)."""

EFFECT_NAMES = ("track_gradient", "tyre_temperature", "airspeed_calibration", "yaw_calibration", "aero_lift",
                "side_force_slip", "pitch_attitude", "driveline_quadratic", "tyre_speed_exponent", "spatial_wind",
                "anemometer_dynamics", "run_to_run_variation", "mass_error", "aero_admittance",
                "tyre_start_temperature")
"""The candidate names of the issue's contract, in library order.  A candidate is one formula;
the physical effect it stands for is its ``cause`` (:attr:`Effect.cause`: its own name unless
the library says which other candidate's effect it is a form of)."""

SIGNS = {"positive": 1, "negative": -1}
"""The physical signs a one-parameter effect may declare (``sign`` in the library)."""

KINDS = ("term", "air", "run")

RESOLVABLE_INPUTS = ("yaw_rad", "airspeed_mps")
"""The logged anemometer channels whose resolution of their own fluctuations the diagnosis
measures (``resolved_inputs`` in the library)."""


@dataclass(frozen=True)
class Effect:
    """One candidate effect of the library.

    Attributes
    ----------
    name : a name of :data:`EFFECT_NAMES`.
    description : what it is.
    terms : drag terms added on top of the user's model.
    kind : "term", "air" (relative-air parameters) or "run" (per-run coefficients).
    prior_sd : parameter -> prior standard deviation around its null (SI).
    null : parameter -> value meaning no effect (a number, or "model": the user's model's value).
    fixed : other parameters of the added terms (SI).
    needs : what a campaign needs to identify the effect.
    confounded_with : coefficients it is known to trade with (documentation).
    sign : parameter -> +1 or -1, the sign of every physical value away from the null (one-
        parameter effects only); an estimate of the other sign is no such effect, and the
        diagnosis scores it at its constrained optimum, the null.
    shape : fixed parameter -> its grid: the family of shapes the candidate is profiled over
        (:func:`fit_shapes`); the ``fixed`` value is the shape before profiling.
    each_run : a term effect whose parameters take one value per run (the shape stays shared):
        e.g. each run's tyres starting at their own temperature.
    resolved_inputs : logged channels (of :data:`RESOLVABLE_INPUTS`) whose fluctuations the
        effect's signature reads: on a campaign whose reading does not resolve them
        (:func:`bayes_roadload.analysis.gap.input_resolution` below
        ``DiagnosisConfig.min_input_lag1``) the effect is not identifiable here.
    form_of : the physical effect the candidate is a form of (library key ``cause``: a
        candidate of the library that is its own cause); "" when it is its own.  :attr:`cause`
        is the effect either way.  Two forms of one cause are not each other's rivals in the
        diagnosis, and a claim of either names the cause.
    """

    name: str
    description: str
    terms: tuple[str, ...]
    kind: str
    prior_sd: dict[str, float]
    null: dict[str, Any] = field(default_factory=dict)
    fixed: dict[str, float] = field(default_factory=dict)
    needs: str = ""
    confounded_with: tuple[str, ...] = ()
    sign: dict[str, int] = field(default_factory=dict)
    shape: dict[str, tuple[float, ...]] = field(default_factory=dict)
    each_run: bool = False
    resolved_inputs: tuple[str, ...] = ()
    form_of: str = ""

    @property
    def cause(self) -> str:
        """The physical effect this candidate stands for (``form_of``, else its own name)."""
        return self.form_of or self.name

    def against_sign(self, estimates: Mapping[str, float]) -> dict[str, float]:
        """The estimates (offsets from the null) whose sign no physical value of the effect has."""
        return {p: float(v) for p, v in estimates.items()
                if p in self.sign and float(v) * self.sign[p] < 0.0}

    @property
    def parameters(self) -> tuple[str, ...]:
        return tuple(self.prior_sd)

    @property
    def per_run(self) -> bool:
        """One value of each parameter per run: kind "run" (the model's coefficients vary from
        run to run) or a term effect with ``each_run``."""
        return self.run_coefficients or self.each_run

    @property
    def run_coefficients(self) -> bool:
        """Kind "run": its parameters are the model's own coefficients, one value per run."""
        return self.kind == "run"

    @property
    def relative_air(self) -> bool:
        """Kind "air": parameters of the relative air (identified with anemometer data only)."""
        return self.kind == "air"


SHAPE_SCALES = ("log", "linear")
"""How a shape grid spaces its points: geometrically (a log-uniform prior) or evenly."""


def shape_grid(where: str, param: str, spec: Mapping[str, Any]) -> tuple[float, ...]:
    """The grid of a shape parameter, ``{low, high, points, scale}`` (``scale`` "log" by
    default): ``points`` values spaced evenly in log or in value from ``low`` to ``high``,
    ends included, each carrying the same prior mass."""
    try:
        low, high, n = float(spec["low"]), float(spec["high"]), int(spec["points"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: shape.{param} needs numbers low, high and points ({exc})") from None
    scale = spec.get("scale", "log")
    if scale not in SHAPE_SCALES:
        raise ValueError(f"{where}: shape.{param}: scale {scale!r} not one of {SHAPE_SCALES}")
    if not (math.isfinite(low) and math.isfinite(high) and low < high and n >= 2):
        raise ValueError(f"{where}: shape.{param}: needs low < high (finite) and at least 2 points")
    if scale == "log" and low <= 0.0:
        raise ValueError(f"{where}: shape.{param}: a log grid needs low > 0")
    grid = np.geomspace(low, high, n) if scale == "log" else np.linspace(low, high, n)
    return tuple(float(f"{v:.12g}") for v in grid)   # 40.0, not 40.00000000000001


def load_library(path: str | Path = LIBRARY_PATH) -> dict[str, Effect]:
    """Read the candidate library (``models/effects/library.toml``); refuses unknown effect
    names, kinds, terms and parameters, and shape grids of parameters the effect does not fix."""
    doc = tomllib.loads(Path(path).read_text())
    out: dict[str, Effect] = {}
    for name, e in doc.get("effects", {}).items():
        where = f"{path}: [effects.{name}]"
        if name not in EFFECT_NAMES:
            raise ValueError(f"{where}: not an effect of the contract ({', '.join(EFFECT_NAMES)})")
        kind = e.get("kind", "term")
        if kind not in KINDS:
            raise ValueError(f"{where}: kind {kind!r} not one of {KINDS}")
        for t in e.get("terms", []):
            if t not in TERMS:
                raise ValueError(f"{where}: unknown drag term {t!r}")
        params = e.get("parameters", {})
        if not params:
            raise ValueError(f"{where}: an effect needs at least one parameter")
        for p in list(params) + list(e.get("fixed", {})):
            if p not in config.PARAMETER_UNITS:
                raise ValueError(f"{where}: unknown parameter {p!r}")
        sign = {}
        for p, v in params.items():
            if "sign" not in v:
                continue
            if v["sign"] not in SIGNS:
                raise ValueError(f"{where}: parameter {p!r}: sign {v['sign']!r} not one of {sorted(SIGNS)}")
            if len(params) != 1 or kind != "term" or v.get("null", 0.0) != 0.0:
                raise ValueError(f"{where}: a sign is for a one-parameter term effect whose null is 0")
            sign[p] = SIGNS[v["sign"]]
        each_run = bool(e.get("each_run", False))
        if each_run and kind != "term":
            raise ValueError(f"{where}: each_run is for a term effect (kind \"run\" is per run already)")
        resolved = tuple(e.get("resolved_inputs", ()))
        for ch in resolved:
            if ch not in RESOLVABLE_INPUTS:
                raise ValueError(f"{where}: resolved_inputs: {ch!r} not one of {RESOLVABLE_INPUTS}")
        form_of = str(e.get("cause", ""))
        if form_of == name:
            form_of = ""
        if form_of and form_of not in EFFECT_NAMES:
            raise ValueError(f"{where}: cause {form_of!r} is not an effect of the contract")
        shape = {}
        for p, spec in e.get("shape", {}).items():
            if p not in e.get("fixed", {}) or kind != "term":
                raise ValueError(f"{where}: shape.{p}: a shape is a fixed parameter of a term effect's terms")
            shape[p] = shape_grid(where, p, spec)
        out[name] = Effect(name=name, description=e.get("description", ""), terms=tuple(e.get("terms", [])),
                           kind=kind, prior_sd={p: float(v["prior_sd"]) for p, v in params.items()},
                           null={p: v.get("null", 0.0) for p, v in params.items()},
                           fixed={k: float(v) for k, v in e.get("fixed", {}).items()},
                           needs=e.get("needs", ""), confounded_with=tuple(e.get("confounded_with", [])),
                           sign=sign, shape=shape, each_run=each_run, resolved_inputs=resolved, form_of=form_of)
    for name, e in out.items():
        if e.form_of and (e.form_of not in out or out[e.form_of].form_of):
            raise ValueError(f"{path}: [effects.{name}]: cause {e.form_of!r} must be a candidate of the library "
                             "that is its own cause")
    return out


def causes(library: Mapping[str, Effect]) -> dict[str, str]:
    """Candidate name -> the physical effect it stands for (:attr:`Effect.cause`)."""
    return {name: e.cause for name, e in library.items()}


# ----------------------------------------------------------------------------- linearisation

@dataclass
class Linearisation:
    """The user's fit and every candidate's signature around it.

    Attributes
    ----------
    columns : names of the parameter columns: the user's free coefficients, then every
        candidate parameter, then ``v0_mps`` (per run).
    base : the user's free coefficients (a prefix of ``columns``).
    effects : effect name -> its parameter columns (run effects: the coefficients, per run).
    available : effect name -> None, or why it cannot be evaluated on this campaign.
    values : parameter values at the linearisation point (the user's MAP, effects at null).
    jacobian : [R, N, k] d speed / d column, zero on padded samples.
    residual : [R, N] measured minus fitted speed (zero on padded samples).
    gram, score : [R, k, k] J^T Sigma^-1 J and [R, k] J^T Sigma^-1 r per run.
    loglik : [R] log likelihood of each run at the fit.
    sigma_mps, q : the fit's noise levels ([R] and scalar).
    model : the super-model; ``batch`` the runs.
    """

    columns: tuple[str, ...]
    base: tuple[str, ...]
    effects: dict[str, tuple[str, ...]]
    available: dict[str, str | None]
    values: dict[str, float]
    jacobian: np.ndarray
    residual: np.ndarray
    gram: np.ndarray
    score: np.ndarray
    loglik: np.ndarray
    sigma_mps: np.ndarray
    q: float
    model: DragModel
    batch: Any
    run_ids: tuple
    speed_fn: Any = None
    x: Any = None
    noise_fns: Any = None

    def index(self, names) -> list[int]:
        return [self.columns.index(n) for n in names]

    @property
    def n_runs(self) -> int:
        return self.residual.shape[0]

    @property
    def n_samples(self) -> int:
        return int(np.asarray(self.batch.mask).sum())


def super_model(base: DragModel, library: Mapping[str, Effect]) -> tuple[DragModel, dict[str, str | None]]:
    """The user's model with every candidate's terms added (at their null they change
    nothing), and for each effect None or the reason it is not available (e.g. anemometer
    calibration without measured air)."""
    names = list(base.term_names)
    terms = list(base.terms)
    available: dict[str, str | None] = {}
    measured = isinstance(base.air, MeasuredAir)
    for e in library.values():
        available[e.name] = None
        if (e.relative_air or any(TERMS[t].needs_measured_air for t in e.terms)) and not measured:
            available[e.name] = "needs logged airspeed_mps and yaw_rad (the model uses no measured air)"
            continue
        for t in e.terms:
            if t not in names:
                names.append(t)
                terms.append(TERMS[t]())
    air = OffsetAir() if measured else base.air
    return DragModel(tuple(terms), air), available


def _null_value(effect: Effect, param: str, model_values: Mapping[str, float], base_has_term: bool,
                model_fixed: Mapping[str, float]) -> float:
    """The value of ``param`` meaning "no effect": the user's model's own value when the model
    has the effect's terms and holds the parameter fixed (the candidate is then a change of that
    value, e.g. a stated cup lag or K_alpha of a model with the pitch term), else the library's
    null (0, or ``"model"``: the model's value where it has the term)."""
    if base_has_term and param in model_fixed:
        return float(model_fixed[param])
    null = effect.null.get(param, 0.0)
    if null == "model":
        return float(model_values.get(param, 0.0)) if base_has_term else 0.0
    return float(null)


def linearisation_point(problem, fit_values: Mapping[str, Any], library: Mapping[str, Effect],
                        admittance_length_m: float = 0.0
                        ) -> tuple[DragModel, dict[str, str | None], dict[str, float], dict[str, tuple[str, ...]],
                                   list[str]]:
    """Where :func:`linearise` differentiates: the super-model (:func:`super_model`), each
    effect's availability, every parameter's value (the user's fit, each candidate at its null:
    :func:`_null_value`), effect name -> its parameter columns, and the columns (the user's free
    coefficients, then the candidates' parameters and shapes; ``v0_mps`` is appended by
    :func:`linearise`)."""
    model, available = super_model(problem.model, library)
    if admittance_length_m > 0.0:
        for e in library.values():
            if available[e.name] is None and any(TERMS[t].felt_air_length for t in e.terms):
                available[e.name] = (f"the model applies the vehicle's admittance already (length "
                                     f"{admittance_length_m:g} m): the candidate would filter the felt air again")
    values = {k: float(v) for k, v in problem.fixed.items()}
    values.update({k: float(np.asarray(fit_values[k])) for k in problem.free})
    base_terms = set(problem.model.term_names)
    effects: dict[str, tuple[str, ...]] = {}
    columns = list(problem.free)
    for e in library.values():
        if available[e.name] is not None:
            continue
        has = all(t in base_terms for t in e.terms) if e.terms else True
        # the terms of the user's model keep its values: the linearisation point is its fit
        values.update({k: v for k, v in e.fixed.items() if not (has and k in problem.fixed)})
        if e.run_coefficients:
            cols = tuple(p for p in e.parameters if p in problem.free)
            if not cols:
                available[e.name] = "the model frees none of its coefficients"
                continue
            effects[e.name] = cols
            continue
        cols = []
        for p in e.parameters:
            if p in problem.free:
                continue  # already estimated by the user's model
            values[p] = _null_value(e, p, values, has, problem.fixed)
            if p not in columns:
                columns.append(p)
            cols.append(p)
        if not cols:
            available[e.name] = "its parameters are already free in the model"
            continue
        effects[e.name] = tuple(cols)
    # shape parameters are columns too (never solved for: at the null their signature is
    # zero), so that fit_shapes can move them without a new compilation
    columns += [p for name in effects for p in library[name].shape if p not in columns]
    for p, v in model.defaults.items():
        values.setdefault(p, float(v))
    return model, available, values, effects, columns


def linearise(problem, fit_values: Mapping[str, Any], library: Mapping[str, Effect],
              admittance_length_m: float = 0.0) -> Linearisation:
    """Differentiate the super-model's speed traces at the user's fit
    (:func:`linearisation_point`).

    Parameters
    ----------
    problem : :class:`~bayes_roadload.inference.bayes.FitProblem` of the user's model (pooled).
    fit_values : constrained values at the fit (the MAP): the free coefficients, ``v0_mps``,
        ``sigma_mps`` and, with integrated noise, ``q_mps_per_sqrt_s``.
    library : the candidates (:func:`load_library`).
    admittance_length_m : the length of the admittance filter the user's model applies to the
        readings (``ModelSpec.resolve_admittance``; 0: none): a candidate whose terms filter
        the readings (``felt_air_length``) is then not applicable.
    """
    model, available, values, effects, columns = linearisation_point(problem, fit_values, library,
                                                                     admittance_length_m)
    columns.append("v0_mps")
    batch = problem.batch
    r = batch.n_runs
    names = tuple(columns[:-1])
    const = {k: jnp.asarray(v) for k, v in values.items() if k not in names}

    def speeds(x):
        params = dict(const, **{n: x[:, i] for i, n in enumerate(names)})
        return integrate_batch(model, params, batch, x[:, -1])[0]

    @jax.jit
    def speed_and_jacobian(x):
        y, f_jvp = jax.linearize(speeds, x)
        k = x.shape[1]
        tangents = jnp.broadcast_to(jnp.eye(k)[:, None, :], (k, r, k))
        return y, jnp.moveaxis(jax.vmap(f_jvp)(tangents), 0, -1)

    v0 = np.asarray(fit_values["v0_mps"], float)
    x0 = np.column_stack([np.full(r, values[n]) for n in names] + [v0])
    mask = np.asarray(batch.mask)
    sigma = np.broadcast_to(np.asarray(fit_values["sigma_mps"], float), (r,)).copy()
    q = float(np.asarray(fit_values.get("q_mps_per_sqrt_s", 0.0)))
    lin = Linearisation(columns=tuple(columns), base=tuple(problem.free), effects=effects, available=available,
                        values=values, jacobian=np.zeros(0), residual=np.zeros(0), gram=np.zeros(0),
                        score=np.zeros(0), loglik=np.zeros(0), sigma_mps=sigma, q=q, model=model, batch=batch,
                        run_ids=tuple(problem.run_ids), speed_fn=speed_and_jacobian)
    return relinearise(lin, x0)


def relinearise(lin: Linearisation, x: np.ndarray) -> Linearisation:
    """``lin`` re-evaluated at the column values ``x`` ([R, k]: every column per run, the
    initial speed last) with the same noise levels (reuses the compiled function)."""
    batch = lin.batch
    mask = np.asarray(batch.mask)
    y, jac = lin.speed_fn(jnp.asarray(x))
    jac = np.where(mask[..., None], np.asarray(jac), 0.0)
    resid = np.where(mask, np.asarray(batch.speed_mps) - np.asarray(y), 0.0)
    g, b = _effect_terms_jit(jnp.asarray(resid), jnp.asarray(batch.time_s), jnp.asarray(batch.mask, bool),
                             jnp.asarray(lin.sigma_mps), jnp.asarray(lin.q), jnp.asarray(jac))
    ll = _loglik_batch_jit(jnp.asarray(resid), jnp.asarray(batch.time_s), jnp.asarray(batch.mask, bool),
                           jnp.asarray(lin.sigma_mps), jnp.asarray(lin.q))
    out = Linearisation(**{**lin.__dict__})
    out.jacobian, out.residual = jac, resid
    out.gram, out.score, out.loglik = np.asarray(g), np.asarray(b), np.asarray(ll)
    out.x = np.asarray(x, float)
    return out


# ----------------------------------------------------------------------------- evaluation

@dataclass
class Solution:
    """The best step of a set of shared and per-run columns (:func:`solve`)."""

    shared: list[int]
    own: list[int]
    beta: np.ndarray              # [S] shared step
    gamma: np.ndarray             # [R, O] per-run steps
    loglik_gain: float            # maximised log likelihood gain over the fit
    cov_shared: np.ndarray        # [S, S] posterior covariance (with the prior ridge)
    cov_own: np.ndarray           # [R, O, O] conditional covariance of each run's own step
    run_terms: list               # per run (H_r, g_r, c_r) of the profiled quadratic
    information: np.ndarray       # [S, S] sum of H_r (no ridge)


def solve(lin: Linearisation, shared: list[int], own: list[int], prior_precision: np.ndarray | None = None,
          own_precision: np.ndarray | None = None, runs: np.ndarray | None = None) -> Solution:
    """Maximise the quadratic log likelihood over a step of the ``shared`` columns (common to
    the runs) and the ``own`` columns (each run its own), with Gaussian ridges
    ``prior_precision`` [S] and ``own_precision`` [O]; ``runs`` restricts the sum to those
    runs (leave-out fits).  The own steps are profiled out run by run (Schur complements)."""
    r = lin.n_runs
    runs = np.arange(r) if runs is None else np.asarray(runs)
    s, o = np.asarray(shared, int), np.asarray(own, int)
    pp = np.zeros(len(s)) if prior_precision is None else np.asarray(prior_precision, float)
    op = np.zeros(len(o)) if own_precision is None else np.asarray(own_precision, float)
    terms = []
    for i in range(r):
        g, b = lin.gram[i], lin.score[i]
        a, bb, d = g[np.ix_(s, s)], g[np.ix_(s, o)], g[np.ix_(o, o)] + np.diag(op)
        bs, bo = b[s], b[o]
        dinv = np.linalg.pinv(d)
        terms.append((a - bb @ dinv @ bb.T, bs - bb @ dinv @ bo, 0.5 * float(bo @ dinv @ bo), dinv, bb, bo))
    info = sum(terms[i][0] for i in runs) if len(s) else np.zeros((0, 0))
    grad = sum(terms[i][1] for i in runs) if len(s) else np.zeros(0)
    if len(s):
        h = info + np.diag(pp)
        scale = np.sqrt(np.maximum(np.diag(h), 1e-300))
        hs = h / np.outer(scale, scale)
        cov = np.linalg.pinv(hs, rcond=1e-12) / np.outer(scale, scale)
        beta = cov @ grad
        gain = float(grad @ beta - 0.5 * beta @ info @ beta)
    else:
        cov, beta, gain = np.zeros((0, 0)), np.zeros(0), 0.0
    gamma = np.zeros((r, len(o)))
    cov_own = np.zeros((r, len(o), len(o)))
    for i in range(r):
        _, _, c, dinv, bb, bo = terms[i]
        gamma[i] = dinv @ (bo - bb.T @ beta)
        cov_own[i] = dinv
    gain += sum(terms[i][2] for i in runs)
    return Solution(shared=list(s), own=list(o), beta=beta, gamma=gamma, loglik_gain=gain, cov_shared=cov,
                    cov_own=cov_own, run_terms=terms, information=info)


def run_loglik_gain(sol: Solution, i: int) -> float:
    """Log likelihood gain of run ``i`` at the shared step ``sol.beta`` with its own step
    profiled."""
    h, g, c, *_ = sol.run_terms[i]
    b = sol.beta
    return float(c + g @ b - 0.5 * b @ h @ b) if len(b) else float(c)


def model_columns(lin: Linearisation, effects: tuple[str, ...], library: Mapping[str, Effect]):
    """Shared and own column indices and their ridges for the user's model plus ``effects``."""
    shared = list(lin.base)
    prior = [0.0] * len(shared)
    own, own_prior = ["v0_mps"], [0.0]
    for name in effects:
        e = library[name]
        for p in lin.effects[name]:
            if e.per_run:
                own.append(p)
                own_prior.append(1.0 / e.prior_sd[p] ** 2)
            elif p not in shared:
                shared.append(p)
                prior.append(1.0 / e.prior_sd[p] ** 2)
    return lin.index(shared), np.asarray(prior), lin.index(own), np.asarray(own_prior)


def fit_effects(lin: Linearisation, effects: tuple[str, ...], library: Mapping[str, Effect],
                runs: np.ndarray | None = None) -> Solution:
    """The user's model plus ``effects``, fitted in the quadratic approximation."""
    s, sp, o, op = model_columns(lin, effects, library)
    return solve(lin, s, o, sp, op, runs)


def n_added_parameters(lin: Linearisation, effects: tuple[str, ...], library: Mapping[str, Effect]) -> int:
    """Parameters the effects add (run effects: one per run and coefficient, less the shared
    one; each-run term effects: one per run and parameter; families: one more per shape
    parameter, profiled over its grid)."""
    k = 0
    for name in effects:
        e = library[name]
        per_param = lin.n_runs - 1 if e.run_coefficients else lin.n_runs if e.each_run else 1
        k += len(lin.effects[name]) * per_param + len(e.shape)
    return k


def fit_shapes(lin: Linearisation, library: Mapping[str, Effect]) -> tuple[Linearisation, dict[str, dict]]:
    """Profile every family's shape parameters (``Effect.shape``) over their grids, each family
    alone on top of the user's model: the grid point whose fit gains the most log likelihood
    (an estimate of a sign no physical value has scores the null, as in the diagnosis).  Where
    no point gains anything the family keeps its ``fixed`` shape.

    Returns the linearisation at every family's best shape -- the other candidates' signatures
    are unchanged, since at the null a shape moves no speed -- and, per family,
    ``{"values": {param: value}, "profile": [{param: value, ..., "loglik_gain": gain}, ...]}``
    (gains over the user's model, one per grid point)."""
    families = [n for n in lin.effects if library[n].shape]
    if not families:
        return lin, {}
    base_gain = fit_effects(lin, (), library).loglik_gain
    x = lin.x.copy()
    values = dict(lin.values)
    out: dict[str, dict] = {}
    moved: list[Linearisation] = []
    for name in families:
        e = library[name]
        params = list(e.shape)
        j = lin.index(params)
        profile, best = [], (0.0, None, None)
        for point in itertools.product(*(e.shape[p] for p in params)):
            xs = lin.x.copy()
            xs[:, j] = point
            ls = relinearise(lin, xs)
            sol = fit_effects(ls, (name,), library)
            shared = [ls.columns[i] for i in sol.shared]
            est = {p: float(ls.values.get(p, 0.0) + sol.beta[shared.index(p)]) for p in lin.effects[name]
                   if p in shared}
            gain = 0.0 if e.against_sign(est) else sol.loglik_gain - base_gain
            profile.append({**dict(zip(params, point)), "loglik_gain": float(gain)})
            if gain > best[0]:
                best = (gain, point, ls)
        if best[1] is not None:
            x[:, j] = best[1]
            values.update(zip(params, best[1]))
            moved.append(best[2])
        out[name] = {"values": {p: float(values[p]) for p in params}, "profile": profile}
    if not moved:
        return lin, out
    # one family moved: its best grid point's linearisation is already the one at x
    shaped = moved[0] if len(moved) == 1 else relinearise(lin, x)
    shaped.values = values
    return shaped, out




def noise_objective(lin: Linearisation):
    """``(objective, value_and_grad, per_run)``, jitted: the negative local-level log
    likelihood of residuals [R, N] on ``lin``'s sample grid as a function of theta = (log
    sigma [R], log q), its gradient, and the [R] log likelihoods; built once per
    linearisation (the grid is a constant of the compiled functions)."""
    if getattr(lin, "noise_fns", None) is None:
        t, m = np.asarray(lin.batch.time_s, float), np.asarray(lin.batch.mask, bool)
        r = t.shape[0]

        def per_run(theta, residual):
            return local_level_loglik_batch(residual, t, m, jnp.exp(theta[:r]), jnp.exp(theta[r]))

        def objective(theta, residual):
            return -jnp.sum(per_run(theta, residual))

        lin.noise_fns = (jax.jit(objective), jax.jit(jax.value_and_grad(objective)), jax.jit(per_run))
    return lin.noise_fns


def fit_noise(lin: Linearisation, residual: np.ndarray) -> tuple[np.ndarray, float]:
    """The noise levels (each run's white-noise sigma [R], the integrated error's q) that
    maximise the local-level likelihood of ``residual`` -- the model's own noise model,
    refitted once a candidate has taken its share of the misfit (a misfit the model cannot
    follow inflates q, and with it every covariance the fit predicts)."""
    from scipy.optimize import minimize

    _, value_and_grad, _ = noise_objective(lin)
    resid = jnp.asarray(residual, float)
    theta0 = np.concatenate([np.log(np.asarray(lin.sigma_mps, float)), [math.log(max(float(lin.q), 1e-12))]])

    def fun(theta):
        v, g = value_and_grad(jnp.asarray(theta), resid)
        return float(v), np.asarray(g, float)

    # sigma within 1 um/s .. 10 m/s, q within 1e-9 .. 10 m/s per sqrt(s): a vanishing level
    # is a boundary, not a direction to follow to -inf
    bounds = [(math.log(1e-6), math.log(10.0))] * (theta0.size - 1) + [(math.log(1e-9), math.log(10.0))]
    theta0 = np.clip(theta0, [b[0] for b in bounds], [b[1] for b in bounds])
    res = minimize(fun, theta0, jac=True, method="L-BFGS-B", bounds=bounds)
    theta = res.x if np.all(np.isfinite(res.x)) else theta0
    return np.exp(theta[:-1]), float(np.exp(theta[-1]))


def with_noise(lin: Linearisation, sigma_mps: np.ndarray, q: float) -> Linearisation:
    """``lin`` at the same point with other noise levels: its information (gram), score and
    log likelihood recomputed (no model evaluation)."""
    batch = lin.batch
    resid = jnp.asarray(lin.residual)
    g, b = _effect_terms_jit(resid, jnp.asarray(batch.time_s), jnp.asarray(batch.mask, bool), jnp.asarray(sigma_mps),
                             jnp.asarray(q), jnp.asarray(lin.jacobian))
    theta = jnp.asarray(np.concatenate([np.log(np.asarray(sigma_mps, float)), [math.log(float(q))]]))
    ll = noise_objective(lin)[2](theta, resid)
    out = Linearisation(**{**lin.__dict__})
    out.gram, out.score, out.loglik = np.asarray(g), np.asarray(b), np.asarray(ll)
    out.sigma_mps, out.q = np.asarray(sigma_mps, float), float(q)
    return out


def refit_residual(lin: Linearisation, sol: Solution) -> np.ndarray:
    """[R, N] residuals after the step of ``sol`` (linear in the step)."""
    out = lin.residual.copy()
    for i in range(lin.n_runs):
        step = np.zeros(len(lin.columns))
        step[sol.shared] += sol.beta
        step[sol.own] += sol.gamma[i]
        out[i] = lin.residual[i] - lin.jacobian[i] @ step
    return out


def step_values(lin: Linearisation, sol: Solution) -> np.ndarray:
    """[R, k] column values after the step of ``sol``."""
    x = lin.x.copy()
    x[:, sol.shared] += sol.beta[None, :]
    x[:, sol.own] += sol.gamma
    return x


def lopo_lpd(lin: Linearisation, effects: tuple[str, ...], library: Mapping[str, Effect], groups) -> float:
    """Leave-one-group-out log predictive density of the user's model plus ``effects``: for
    each group (e.g. an opposite-direction pair, as run indices) the shared parameters are
    fitted without its runs, and its runs scored at them, each with its own initial speed
    (and, for run effects, its own coefficients) fitted: those are the run's own nuisances,
    not predictions.  Quadratic approximation about the user's fit; the sum over groups."""
    total = 0.0
    everything = np.arange(lin.n_runs)
    for grp in groups:
        train = np.setdiff1d(everything, np.asarray(grp))
        sol = fit_effects(lin, effects, library, runs=train)
        total += sum(float(lin.loglik[i]) + run_loglik_gain(sol, i) for i in grp)
    return total


def _conditional_ratio(info: np.ndarray, j: int, others: list[int] | None = None) -> float:
    """Share of column j's Fisher information left once ``others`` (default: every other
    column of ``info``) are fitted too: 1 - R^2 of its signature on theirs."""
    others = [i for i in range(info.shape[0]) if i != j] if others is None else others
    marginal = info[j, j]
    if marginal <= 0:
        return 0.0
    if not others:
        return 1.0
    sub = info[np.ix_(others, others)]
    cross = info[np.ix_([j], others)][0]
    scale = np.sqrt(np.maximum(np.diag(sub), 1e-300))
    cond = marginal - cross / scale @ np.linalg.pinv(sub / np.outer(scale, scale), rcond=1e-12) @ (cross / scale)
    return float(max(cond, 0.0) / marginal)


def distinct_share(lin: Linearisation, effect: str, rival: str, library: Mapping[str, Effect]) -> float:
    """How much of ``effect``'s signature is its own against ``rival``'s: for each of its
    parameters, the Fisher information left with the user's coefficients *and* the rival's
    parameters fitted, as a share of that left with the coefficients alone; the largest over
    its parameters (1: nothing in common, 0: the rival mimics it entirely).  Run effects and
    effects without shared parameters give 1 (they are told apart by other means)."""
    if library[effect].per_run or library[rival].per_run:
        return 1.0
    sol = fit_effects(lin, (effect, rival), library)
    names = [lin.columns[j] for j in sol.shared]
    mine = [names.index(p) for p in lin.effects[effect] if p in names]
    theirs = {names.index(p) for p in lin.effects[rival] if p in names}
    if not mine or not theirs:
        return 1.0
    shares = []
    for j in mine:
        base = [i for i in range(len(names)) if i != j and i not in theirs]
        alone = _conditional_ratio(sol.information, j, base)
        shares.append(_conditional_ratio(sol.information, j) / alone if alone > 0 else 0.0)
    return float(max(shares))


def identifiability(lin: Linearisation, effect: str, library: Mapping[str, Effect],
                    support_delta_elpd: float = config.DEFAULT_DIAGNOSIS.support_delta_elpd) -> dict[str, Any]:
    """For each shared parameter of ``effect`` added to the user's model: the fraction of its
    Fisher information left once the user's coefficients are re-fitted
    (``information_ratio`` = 1 - R^2 of its speed signature on theirs, through the residual
    covariance), the contraction of its prior (1 - posterior var / prior var), and
    ``detectable``: the smallest offset from its null at which a delta_elpd of
    ``support_delta_elpd`` is expected, sqrt(2 (support + k / 2) / I_c), with I_c that
    conditional Fisher information and k the effect's parameters (a true offset theta gains
    theta^2 I_c / 2 + k / 2 in expectation; delta_elpd subtracts k).  Run effects are per run
    and need no such check (returned empty)."""
    e = library[effect]
    if e.per_run:
        return {}
    sol = fit_effects(lin, (effect,), library)
    k = n_added_parameters(lin, (effect,), library)
    shared_names = [lin.columns[j] for j in sol.shared]
    out = {}
    for p in lin.effects[effect]:
        j = shared_names.index(p)
        ratio = _conditional_ratio(sol.information, j)
        info_c = ratio * float(sol.information[j, j])
        prior_var = e.prior_sd[p] ** 2
        out[p] = {"information_ratio": ratio, "contraction": float(1.0 - sol.cov_shared[j, j] / prior_var),
                  "estimate": float(lin.values.get(p, 0.0) + sol.beta[j]), "sd": float(math.sqrt(max(sol.cov_shared[j, j], 0.0))),
                  "detectable": math.sqrt(2.0 * (support_delta_elpd + k / 2.0) / info_c) if info_c > 0 else math.inf}
    return out


def birge_ratio(estimates: np.ndarray, covariances: np.ndarray) -> tuple[float, float]:
    """The runs' coefficient vectors ``estimates`` [R, P] (covariances [R, P, P]) against
    their precision-weighted mean: ``(sqrt(chi2 / dof), p-value)`` with chi2 the sum of the
    Mahalanobis distances and dof = (R - 1) P.  The ratio is ~1 (sd sqrt(1 / (2 dof))) when
    the runs differ by their noise only; the p-value is chi2's upper tail.  The full
    covariances matter: within one run A_D, B_D, C_D0 are ~0.99 correlated, a run-to-run change
    shows in the combination they pin down, not in each coefficient's wide marginal."""
    from scipy.stats import chi2 as chi2_dist

    est = np.asarray(estimates, float)
    prec = np.linalg.pinv(np.asarray(covariances, float))
    mean = np.linalg.lstsq(prec.sum(0), np.einsum("rij,rj->i", prec, est), rcond=None)[0]
    dev = est - mean
    chi2 = float(np.einsum("ri,rij,rj->", dev, prec, dev))
    dof = (est.shape[0] - 1) * est.shape[1]
    if dof <= 0:
        return math.nan, math.nan
    return math.sqrt(max(chi2, 0.0) / dof), float(chi2_dist.sf(chi2, dof))


def coefficient_spread(lin: Linearisation, sol: Solution | None, library: Mapping[str, Effect]) -> dict[str, float]:
    """Excess between-run spread of the coefficients: each run's own A_D, B_D, C_D0 (those the
    model frees) fitted on top of the model's fit ``sol`` (None: the fit itself), against the
    spread their conditional covariances predict for the same conditions and noise.

    Returns ``spread_excess`` and ``spread_p_value`` (:func:`birge_ratio` of the runs'
    coefficient vectors: ~1 and uniform when the runs differ by noise only) and, per
    coefficient P, ``spread_pct_P`` (std over runs, % of the coefficient),
    ``spread_predicted_pct_P`` (root mean conditional variance, %) and ``spread_excess_P``
    (their ratio).  The per-coefficient ratios use each run's wide marginal variances (and the
    fitted noise level, which a misfit inflates): they can fall below 1 where ``spread_excess``
    is well above it."""
    coeffs = [p for p in ("AD", "BD", "CD0") if p in lin.base]
    if not coeffs or lin.n_runs < 2:
        return {}
    shared = sol.shared if sol is not None else lin.index(lin.base)
    beta = sol.beta if sol is not None else np.zeros(len(shared))
    own = lin.index(["v0_mps"] + coeffs)
    # a refit's own steps of effect parameters (a run-level term family) held at their values
    held = [(k, j) for k, j in enumerate(sol.own) if j not in own] if sol is not None else []
    # each run's own coefficients (and initial speed) given the shared fit: run-level estimates
    r = lin.n_runs
    est = np.zeros((r, len(coeffs)))
    var = np.zeros((r, len(coeffs)))
    cov = np.zeros((r, len(coeffs), len(coeffs)))
    for i in range(r):
        g, b = lin.gram[i], lin.score[i]
        d = g[np.ix_(own, own)]
        rhs = b[own] - g[np.ix_(own, shared)] @ beta
        if held:
            rhs = rhs - g[np.ix_(own, [j for _, j in held])] @ sol.gamma[i, [k for k, _ in held]]
        dinv = np.linalg.pinv(d)
        est[i] = (dinv @ rhs)[1:]
        var[i] = np.diag(dinv)[1:]
        cov[i] = dinv[1:, 1:]
    ratio, p_value = birge_ratio(est, cov)
    out = {"spread_excess": ratio, "spread_p_value": p_value}
    for k, p in enumerate(coeffs):
        centre = lin.values[p] + (beta[shared.index(lin.columns.index(p))] if lin.columns.index(p) in shared else 0.0)
        observed = float(np.std(est[:, k], ddof=1))
        predicted = float(np.sqrt(np.mean(var[:, k])))
        out[f"spread_pct_{p}"] = 100.0 * observed / abs(centre)
        out[f"spread_predicted_pct_{p}"] = 100.0 * predicted / abs(centre)
        out[f"spread_excess_{p}"] = observed / predicted if predicted > 0 else math.nan
    return out


def airspeed_kinematics(problem, campaign, stated_factor: float,
                        yaw_factor: float | None = None) -> dict[str, float] | None:
    """The airspeed scale from the paired runs' kinematics (thesis 4.7.3): each
    opposite-direction pair's ratio of mean ground speed to mean along-track airspeed reading
    (:func:`~bayes_roadload.inference.bayes.airspeed_pair_ratios`) estimates the true factor.
    Returns the mean ratio, its standard error (the pairs' scatter, at least
    ``config.NOISE_PRIORS["airspeed_calibration_sd"]`` per pair), the z-score against the
    factor the model uses and the log likelihood gain of the ratios with the factor free
    (z^2 / 2); None without pairs or measured air.  ``yaw_factor`` overrides the model's vane
    factor (the along-track airspeed is a cos(psi))."""
    from ..inference.bayes import airspeed_pair_ratios, calibration_pairs

    if not campaign.has_anemometer:
        return None
    pairs = calibration_pairs(campaign, problem.run_ids)
    if not pairs:
        return None
    yaw_factor = float(problem.fixed.get("yaw_factor", 1.0)) if yaw_factor is None else float(yaw_factor)
    ratios = np.asarray(airspeed_pair_ratios(problem.batch, pairs, yaw_factor))
    k = ratios.size
    sd = max(float(np.std(ratios, ddof=1)) if k > 1 else 0.0, config.NOISE_PRIORS["airspeed_calibration_sd"])
    se = sd / math.sqrt(k)
    z = (float(ratios.mean()) - stated_factor) / se
    return {"factor": float(ratios.mean()), "se": se, "n_pairs": k, "z": z, "loglik_gain": 0.5 * z * z}


def kinematic_conflict(dynamics: Mapping[str, float] | None, kinematics: Mapping[str, float]) -> float:
    """The log likelihood lost when one airspeed factor must serve both the dynamics (estimate
    and sd from :func:`identifiability`) and the paired-run kinematics (factor and se of
    :func:`airspeed_kinematics`): each gain is a Gaussian in the factor, so the joint maximum
    is the sum of the two maxima less (f_dyn - f_kin)^2 / (2 (sd_dyn^2 + se_kin^2))."""
    if dynamics is None or not math.isfinite(dynamics.get("sd", math.nan)):
        return 0.0
    var = dynamics["sd"] ** 2 + kinematics["se"] ** 2
    return float((dynamics["estimate"] - kinematics["factor"]) ** 2 / (2.0 * var)) if var > 0 else 0.0
