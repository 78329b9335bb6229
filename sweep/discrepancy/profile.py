"""The profile-likelihood interval of a named effect's strength (the re-centring of a fit on the profile's
minimum: :mod:`.recentre`).

The Wald interval trusts a linearization at the fit; when the effect's signature saturates or trades against
a calibrated parameter along a curved valley (β against E: a smaller β with a stiffer E reproduces the early
pressure) it is falsely narrow.  The profile refits the other parameters with the strength held at trial
values; the interval is where the profile's χ² rises by less than ``level``·scale (3.84: 95 % for one
parameter; scale: the misfit scale of the Wald interval; ``[profile] threshold = "f_realizations"`` or
``"f_welch"``: level the F(1, ν) quantile of the same probability, ν = k − 1 (k the mesh realizations) or the
Welch–Satterthwaite degrees of freedom of the strength's variance with its realization part known to k − 1:
:meth:`~.noise.NoiseModel.threshold_dof`).  Which χ² is ``[profile] likelihood``: "weighted"
(per-series weights n_eff/n from the fit's lag-1 autocorrelation, for correlations no covariance models),
"gaussian" (the whitened χ², −2 ln of the Gaussian likelihood with the modelled covariance: the exact
interval of a linear model) or "marginal" (the realization covariance's scale integrated over its sampling
distribution from k realizations).  Settings: :class:`~.options.ProfileOptions`.  Units: each parameter's own; Δχ² dimensionless.

Which discretization correction each point is compared under (``[profile] fine``, ``correction``): the fit's
(``fine = false``), re-estimated at each point from the fine realizations (``correction = "point"``), or
modelled linearly in the strength from the realizations at a few anchor strengths (``"linear"``,
:class:`StrengthCorrection`), or piecewise linearly through them with an anchor added wherever the profile goes
beyond them (``"piecewise"``, :class:`~.linear_correction.PiecewiseCorrection`, :meth:`_Profile.extend_correction`:
never extrapolated, for a correction that switches on and saturates within the profile's reach; an added anchor
leaves the function between the others as it was).  The linear model is fixed once per profile and kept through its re-centrings, so
every point is evaluated with the same realizations, the same correction function and the same covariance
(common random numbers): Δχ² differences then come from the strength alone, and the profile is as smooth as
the coarse model.  ``[profile] correction_follows``: the model is linear in the strength alone ("strength") or
in every parameter of the fit ("all": two more anchors per calibrated parameter), and each refit of the profile
and the named model's settling (:func:`.recentre.settled_fit`) evaluate it at their own trial parameters
(:meth:`~.noise.NoiseModel.following`), so they are optima of the likelihood with the correction where each
model is, not fixed points of "correct, then refit" (results/discrepancy/ten_minute_twin/diagnosis/, finding 1); a point-wise correction carries the fine realizations' own jitter in the parameters into
every point (measured on the toy, tests/test_discrepancy_crn.py).  A profile that is not monotone on each side
of its lowest point is flagged (``non_monotone``); a re-centring (:mod:`.recentre`) is recorded in ``recentred``
and reported.
"""
from __future__ import annotations

import logging
import math
from contextlib import contextmanager

import numpy as np

from . import stats
from .emulator import AGREE_SD, CurveEmulator, design_points, fill_design, fit_on_emulator, wald_box
from .evidence import wald_bounds
from .linear_correction import PiecewiseCorrection, StrengthCorrection
from .noise import coarse_and_fines, correction_at, correction_from
from .problem import Fit, Problem
from .realizations import realizations
from .report import jsonable

log = logging.getLogger("dchfrac.discrepancy")

__all__ = ["profile_interval", "emulator_for", "StrengthCorrection"]


class _Profile:
    """The profile of parameter ``j`` of ``fit`` on the conditions ``ids``: its evaluated points and the
    bracketing of each bound (see :func:`profile_interval`)."""

    def __init__(self, problem, fit: Fit, j: int, ids, level: float, fine_forward, emulator=None,
                 correction: StrengthCorrection | None = None):
        self.problem, self.fit, self.j, self.ids = problem, fit, j, ids
        self.em, self.last = emulator, None
        self.po = problem.spec.profile
        self.mask = problem.mask(ids)
        # [profile] threshold: χ²(1) (the default asks nothing of the noise model), or F(1, ν) at its probability
        self.dof = (math.inf if self.po.threshold == "chi2"
                    else problem.noise.threshold_dof(self.po.threshold, fit.J, j, self.mask))
        self.level = stats.realization_level(level, self.dof)
        self.x_hat = np.asarray(fit.x, float)
        self.p = fit.params[j]
        self.free = fit.params[:j] + fit.params[j + 1:]
        self.w = (stats.series_weights(fit.r, problem.series[self.mask]) if self.po.likelihood == "weighted"
                  else np.ones(fit.r.size))
        chi2_w, n = stats.effective_chi2(fit.r, self.w)
        self.thr = self.level * max(1.0, chi2_w / max(n - len(fit.params), 1.0))
        self.x_lo, self.x_hi = self.p.x_bounds
        self.wald = wald_bounds(fit, j, self.w)[:2]
        self.points = [{"value": self.p.from_x(self.x_hat[j]), "delta_chi2": 0.0}]
        self.fines = realizations(fine_forward)
        self.checks: list = []
        self.open: set = set()           # the sides (-1, +1) not crossed within the parameter's range
        self.unconverged: dict = {}      # "lower"/"upper": a refined bound's bracket left off the threshold
        self.point_correction = None     # with fine models: the correction at the last point dchi2 evaluated
        self.cm = None                   # with [profile] correction = "linear" or "piecewise": its model
        if self.fines and self.po.correction in ("linear", "piecewise"):
            self.cm = correction if correction is not None else self.linear_correction()
        # the fit's χ² under the correction it was made under, taken as the points' are: on the emulator (its
        # covariance at the fit too) when there is one, so that Δχ² stays within one likelihood
        self.chi2_fit = self.deviance(fit.r) if emulator is None else self.fit_deviance(self.held(float(fit.x[j])))
        self.chi2_hat = self.reference_deviance() if self.fines else self.chi2_fit

    def linear_correction(self) -> StrengthCorrection:
        """The correction modelled linearly (:class:`StrengthCorrection`) in the strength, or with ``[profile]
        correction_follows = "all"`` in every parameter of the fit: estimated from the fine realizations at the
        anchors (:meth:`anchors`); on the emulator each taken against the emulator's mean
        (:meth:`model_correction`).  With ``correction_slope_realizations`` = m > 0 the anchors after the first
        run the first m realizations only (:func:`~.noise.correction_from` with the first anchor's as
        reference).  With ``correction_realizations`` = m (2 <= m < k) every anchor runs the first m
        realizations, and from there on (the profile's points, its re-centring, the named model after it) the
        noise model's covariance carries the m-mean's error (:meth:`~.noise.NoiseModel.correction_mean_of`);
        the anchors are placed under the fit's noise model, as under the fit's correction."""
        follows_all = self.po.correction_follows == "all"
        mean_of = self.po.correction_realizations
        fines_used = self.fines[:mean_of] if 2 <= mean_of < len(self.fines) else self.fines
        if len(fines_used) < len(self.fines):
            self.problem.noise.correction_mean_of(0)       # a rebuilt model's anchors too: the k-mean's
        anchors, n_strength = self.anchors()
        if len(fines_used) < len(self.fines):
            self.problem.noise.correction_mean_of(len(fines_used))
        corrs, real, first = [], [], None
        m = self.po.correction_slope_realizations
        for full, at in anchors:
            if first is None or not 0 < m < len(self.fines):
                c, fines = self.fine_correction(full, fines_used)
                first = fines if first is None else first
            else:                            # the first anchor's mean carried here by m realizations' change
                c, _ = self.fine_correction(full, self.fines[:m], ref=first)
            real.append(c)
            corrs.append(self.model_correction(real[-1], at))
        X = np.array([full if follows_all else full[self.j] for full, _ in anchors])
        values = [float(self.p.from_x(full[self.j])) for full, _ in anchors[:n_strength]]
        kw = {"params": self.fit.params if follows_all else (self.p,), "strength": self.j if follows_all else 0}
        model = PiecewiseCorrection if self.po.correction == "piecewise" else StrengthCorrection
        cm = model(X, corrs, values, real=model(X, real, values, **kw) if self.em else None, **kw)
        cm.realizations = len(fines_used)
        cm.slope_realizations = m if 0 < m < len(self.fines) else len(fines_used)
        return cm

    def anchors(self) -> tuple[list, int]:
        """The linear correction's anchors as (the point in all the fit's parameters, fit coordinates; where
        the model's correction is taken: a refit or that point, :meth:`model_correction`), and how many of them
        are strength anchors (the first): ``correction_anchors`` strengths evenly over the fit ±
        ``correction_span`` Wald half-widths (clipped to the bounds), the others refitted at each under the
        fit's correction; with ``correction_follows = "all"`` then, per calibrated parameter, the fit displaced
        along it by ± ``correction_span`` of its Wald half-widths (clipped; a displacement the bound leaves
        at zero is dropped), the others as at the fit."""
        po, xh = self.po, float(self.x_hat[self.j])
        xs = np.unique(np.clip(xh + po.correction_span * self.half_width(self.j)
                               * np.linspace(-1.0, 1.0, po.correction_anchors), self.x_lo, self.x_hi))
        if xs.size < 2:
            xs = np.array([self.x_lo, self.x_hi])
        out = [self.strength_anchor(float(x)) for x in xs]
        if po.correction_follows == "all":
            for i, q in enumerate(self.fit.params):
                lo, hi = q.x_bounds
                for sign in ((-1.0, 1.0) if i != self.j else ()):
                    full = np.array(self.x_hat, float)
                    full[i] = float(np.clip(full[i] + sign * po.correction_span * self.half_width(i), lo, hi))
                    if full[i] != self.x_hat[i]:
                        out.append((full, full))
        return out, xs.size

    def strength_anchor(self, xj: float) -> tuple[np.ndarray, Fit]:
        """An anchor at the strength's coordinate ``xj``: the point in all the fit's parameters (fit
        coordinates), the others refitted there under the fit's correction, and that refit."""
        f = self.held(xj)
        return np.insert(np.asarray(f.x, float), self.j, xj), f

    def fine_correction(self, full, fines, ref=None) -> tuple[np.ndarray, list]:
        """The correction (fine minus coarse, per curve row) of the realizations ``fines`` at the point ``full``
        (fit coordinates, all parameters), and their runs; ``ref``: :func:`~.noise.correction_from`'s."""
        coarse, runs = coarse_and_fines(self.problem, fines,
                                        {q.name: q.from_x(float(v)) for q, v in zip(self.fit.params, full)})
        return correction_from(coarse, runs, ref=ref), runs

    def half_width(self, i: int) -> float:
        """Half the Wald interval of the fit's parameter ``i`` (fit coordinates); where it is undetermined,
        0.1 of |x| (at least 1e-3 of the parameter's range)."""
        q, xi = self.fit.params[i], float(self.x_hat[i])
        wald = self.wald if i == self.j else wald_bounds(self.fit, i, self.w)[:2]
        wl, wh = (q.to_x(b) if np.isfinite(b) else np.nan for b in wald)
        lo, hi = q.x_bounds
        return 0.5 * abs(wh - wl) if np.isfinite(wh - wl) and wh != wl else 0.1 * max(abs(xi), 1e-3 * (hi - lo))

    def reference_deviance(self) -> float:
        """With fine models, the χ² every Δχ² is measured from: the fit's own point taken as each profile point
        is (:meth:`dchi2`), under the correction re-estimated at the fit with the others refitted under it.  The
        fit was made under the correction of the last refresh pass, estimated at that pass's start; measured
        from that χ², every point's Δχ² would carry the difference of the two corrections as a common offset
        (an offset above the threshold collapses the interval onto the fit)."""
        xj = float(self.x_hat[self.j])
        with self.holding(xj):
            if self.cm is not None:
                f = self.modelled_refit(xj)
            else:
                f, _ = self.corrected_refit(xj, self.fit.values(), self.x_hat, np.delete(self.x_hat, self.j))
        return self.fit_deviance(f)

    def modelled_refit(self, xj: float) -> Fit:
        """The others refitted from the fit's values with the parameter at ``xj`` (held by the caller) under
        the modelled correction (:class:`StrengthCorrection`), the same function for every point, evaluated at
        each trial point of the refit (:meth:`NoiseModel.following`): c(xj) throughout when it follows the
        strength alone, c(xj, others) at the trial others with ``correction_follows = "all"``, so the refit
        sees the correction's derivative in the others.  ``point_correction``: c at the refit."""
        with self.problem.noise.following(self.cm):
            f = self.refit(xj, np.delete(self.x_hat, self.j))
        self.point_correction = self.cm({**f.values(), self.p.name: self.p.from_x(xj)})
        return f

    @contextmanager
    def holding(self, xj: float):
        """The parameter held at ``xj`` (internal coordinates) in ``problem.fixed`` for the refits inside."""
        self.problem.fixed = {self.p.name: self.p.from_x(xj)}
        try:
            yield
        finally:
            self.problem.fixed = {}

    def corrected_refit(self, xj: float, values: dict, at, x0: np.ndarray) -> tuple:
        """The others refitted from ``x0`` with the parameter at ``xj`` (held by the caller,
        :meth:`holding`), under the correction re-estimated at ``values`` and taken as the model needs it at
        ``at`` (:meth:`model_correction`).  Returns (the refit, the correction from real runs)."""
        corr = correction_at(self.problem, self.fines, values)
        old = self.problem.noise.shift_correction(self.model_correction(corr, at))
        try:
            return self.refit(xj, x0), corr
        finally:
            self.problem.noise.shift_correction(old)

    def model_correction(self, corr: np.ndarray, at) -> np.ndarray:
        """The correction ``corr`` (fine − coarse, real runs at a point) as the profile's model needs it there.
        On real runs that is ``corr``.  On the emulator the model is the emulator's mean, so the coarse part
        is that mean: fine − mean = corr + (real coarse run − mean) on the emulator's rows.  With ``corr``
        alone the real run's own jitter about the emulator's smooth part (the nugget) would stay in every
        emulated point's residuals, where a real-run profile cancels it against the run itself.  ``at``: the
        point, a Fit of the emulator (its ``x_full``) or the full parameter vector."""
        if self.em is None:
            return corr
        x = np.asarray(getattr(at, "x_full", at), float)
        gap = self.em.model_vectors([x])[0] - self.em.predict(x)[0]
        out = np.array(corr, float)
        out[self.em.mask] += np.where(np.isfinite(gap), gap, 0.0)
        return out

    def deviance(self, r: np.ndarray) -> float:
        """The profile's χ² of residuals ``r``: Σ w r² ("weighted", "gaussian": w = 1) or −2 ln of the
        likelihood with the realization covariance's scale integrated out ("marginal",
        :meth:`NoiseModel.marginal_deviance`)."""
        if self.po.likelihood == "marginal":
            return self.problem.noise.marginal_deviance(r, self.mask)
        return stats.effective_chi2(r, self.w)[0]

    def dchi2(self, xj: float) -> float:
        """Δχ² with the parameter held at ``xj`` (internal coordinates), the others refitted (on the emulator
        when there is one: :meth:`refit`); with fine models the correction is re-estimated at
        that point and the others refitted again (σ and the covariance stay the fit's, so every Δχ² is on one
        scale)."""
        p = self.p
        row = {"value": p.from_x(xj)}
        if self.cm is not None and self.cm.beyond(xj):
            self.extend_correction(xj)
        with self.holding(xj):
            f = self.modelled_refit(xj) if self.cm is not None else self.refit(xj, np.delete(self.x_hat, self.j))
            if self.fines and self.cm is None:
                row["delta_chi2_fit_correction"] = float(self.fit_deviance(f) - self.chi2_fit)
                f, self.point_correction = self.corrected_refit(xj, {**f.values(), p.name: p.from_x(xj)}, f,
                                                                np.array(f.x, float))
        d = float(self.fit_deviance(f) - self.chi2_hat)
        row.update({"delta_chi2": d, "others": jsonable(f.values())})
        if self.em is not None:
            row["emulated"] = True
        self.points.append(row)
        log.info("profile %s = %.5g: delta chi2 %.2f (threshold %.2f), point %d", p.name, row["value"], d,
                 self.thr, len(self.points) - 1)
        return d

    def extend_correction(self, xj: float) -> None:
        """An anchor of the piecewise correction at ``xj`` (internal coordinates, beyond its anchors), placed as
        the first anchors are (:meth:`strength_anchor`, :meth:`fine_correction`; :meth:`PiecewiseCorrection.add`)."""
        full, f = self.strength_anchor(xj)
        real, _ = self.fine_correction(full, self.fines)
        self.cm.add(xj, self.model_correction(real, f), float(self.p.from_x(xj)), real)
        log.info("profile %s: piecewise correction anchored at %.5g (%d anchors)", self.p.name, self.p.from_x(xj),
                 len(self.cm.values))

    def held(self, xj: float) -> Fit:
        """The others refitted with the parameter held at ``xj`` (from the fit's values)."""
        with self.holding(xj):
            return self.refit(xj, np.delete(self.x_hat, self.j))

    def fit_deviance(self, f: Fit) -> float:
        """The profile's χ² of a refit: :meth:`deviance` of its residuals.  An emulated refit's are whitened
        with the emulator's covariance added (with "marginal": added to every member of the scale mixture,
        :meth:`~.emulator.CurveEmulator.marginal_deviance`), so its error only lowers Δχ² and widens the
        interval; the Gaussian likelihood's log-determinant of that covariance is left out: it grows where the
        emulator knows less, along the profile away from its design, and would narrow the interval by the
        emulator's ignorance."""
        if self.em is not None and self.po.likelihood == "marginal":
            return f.marginal_deviance
        return self.deviance(f.r)

    def refit(self, xj: float, x0: np.ndarray) -> Fit:
        """The others refitted with the parameter at ``xj``: real runs, or the emulator, refined with a real
        run where the predictive sd of its smooth part at the refit exceeds ``emulator_tol`` and the run's own
        jitter (the nugget's sd: below it more runs do not help, and it stays in the likelihood's covariance);
        at most 3 runs a point."""
        if self.em is None:
            return self.problem.fit(self.free, [x0], self.ids)
        for _ in range(3):
            f = fit_on_emulator(self.em, self.j, xj, x0)
            if self.em.sd_norm(f.x_full) <= max(self.po.emulator_tol, self.em.jitter_norm()):
                break
            self.em.add([f.x_full])
            self.em.refinements += 1
        if self.po.likelihood == "marginal":      # under the correction in use now, as the residuals f.r
            f.marginal_deviance = self.em.marginal_deviance(f.x_full)
        self.last = f
        return f

    def confirm(self, sign: int, xb: float) -> float:
        """An emulated interval end ``xb`` checked with a real run at its profile point: the run joins the
        design, and while it disagrees with the emulator beyond max(``emulator_tol``, AGREE_SD × the
        emulator's sd) the side is recomputed on the refined emulator (at most ``emulator_checks`` runs).
        Each check is kept in ``self.checks`` with the real Δχ² there (an upper bound of the real profile's:
        the others are the emulated refit's)."""
        em = self.em
        for _ in range(self.po.emulator_checks):
            d_em = self.dchi2(xb)
            x = self.last.x_full
            u, m = em.sd_norm(x, run=True), em.model_vectors([x])[0]
            dev = em.deviation(x, m)
            agree = bool(dev <= max(self.po.emulator_tol, AGREE_SD * u))
            self.checks.append({"side": "lower" if sign < 0 else "upper", "value": float(self.p.from_x(xb)),
                                "delta_chi2_emulated": d_em, "delta_chi2_real": self.real_dchi2(m),
                                "deviation": dev, "emulator_sd": u, "agrees": agree})
            em.add([x], m[None, :])
            if agree:
                self.check_end(sign, d_em)
                break
            xb = self.side(sign)
        return xb

    def check_end(self, sign: int, d_end: float) -> None:
        """The profile evaluated at a reported end (Δχ² ``d_end``): within ``refine_tol`` of the threshold it
        confirms the end (its side cleared from ``self.unconverged``), else that Δχ² is recorded there."""
        side = "upper" if sign > 0 else "lower"
        if abs(d_end - self.thr) <= self.po.refine_tol * self.thr:
            self.unconverged.pop(side, None)
        else:
            self.unconverged.setdefault(side, {})["delta_chi2_at_end"] = float(d_end)

    def real_dchi2(self, m: np.ndarray) -> float:
        """Δχ² of a real run's model vector ``m`` at the last profile point, under the correction that point's
        emulated Δχ² was taken with (its own, with fine models; else the fit's)."""
        problem = self.problem
        old = problem.noise.shift_correction(self.point_correction) if self.fines else None
        try:
            r = problem.standardize(problem.y[self.mask] - m, self.mask, problem.spec.fit.nan_residual)
            return float(self.deviance(r) - self.chi2_hat)
        finally:
            if self.fines:
                problem.noise.shift_correction(old)

    def cross(self, x_in: float, d_in: float, x_out: float, d_out: float) -> float:
        """The threshold's crossing, √Δχ² interpolated linearly between an inside and an outside point (exact
        for a quadratic profile; linear in Δχ² would put the bound too close to the fit in a wide bracket)."""
        a, b = math.sqrt(max(d_in, 0.0)), math.sqrt(d_out)
        return x_in + (math.sqrt(self.thr) - a) / (b - a) * (x_out - x_in)

    def refine(self, x_in: float, d_in: float, x_out: float, d_out: float) -> float:
        """The bound by regula falsi in √Δχ²: a bracket closed by a point far outside leaves the bound to the
        quadratic assumption, so the profile is evaluated at the interpolated bound and re-bracketed until Δχ²
        there is within ``refine_tol`` of the threshold, at most ``refine`` times.  A bound whose final bracket
        has neither end within ``refine_tol`` of the threshold is an interpolation the profile has not
        confirmed: its bracket and Δχ² there are kept in ``self.unconverged`` (:meth:`mark_converged`)."""
        xb = self.cross(x_in, d_in, x_out, d_out)
        for _ in range(self.po.refine):
            db = self.dchi2(xb)
            if db >= self.thr:
                x_out, d_out = xb, db
            else:
                x_in, d_in = xb, db
            xb = self.cross(x_in, d_in, x_out, d_out)     # the tightest bracket's bound, also when stopping
            if abs(db - self.thr) <= self.po.refine_tol * self.thr:
                break
        self.mark_converged(x_in, d_in, x_out, d_out)
        return xb

    def mark_converged(self, x_in: float, d_in: float, x_out: float, d_out: float) -> None:
        """Record the side of the bracket (``x_in`` inside, ``x_out`` outside, fit coordinates) as unconverged
        in ``self.unconverged`` (its bracket in the parameter's units, Δχ² at its ends) when neither end is
        within ``refine_tol`` of the threshold, else clear it."""
        side = "upper" if x_out > x_in else "lower"
        if min(abs(d_in - self.thr), abs(d_out - self.thr)) <= self.po.refine_tol * self.thr:
            self.unconverged.pop(side, None)
            return
        ends = sorted(((self.p.from_x(x_out), d_out), (self.p.from_x(x_in), d_in)))
        self.unconverged[side] = {"bracket": [float(v) for v, _ in ends], "delta_chi2": [float(d) for _, d in ends]}

    def side(self, sign: int) -> float:
        """One bound: from the Wald bound, doubling the distance from the fit (``expand`` times) until the
        threshold is crossed, then at the parameter's bound itself; where it is not crossed there either, the
        parameter's bound, and the side is open (``self.open``: the range is all the profile excludes)."""
        xh = float(self.x_hat[self.j])
        bound = self.x_hi if sign > 0 else self.x_lo
        step = max(abs(self.p.to_x(self.wald[1] if sign > 0 else self.wald[0]) - xh), 1e-6 * (self.x_hi - self.x_lo))
        x_in, d_in = xh, 0.0
        for k in range(self.po.expand + 2):
            xt = float(np.clip(xh + sign * step, self.x_lo, self.x_hi)) if k <= self.po.expand else bound
            if xt == x_in:
                break
            d = self.dchi2(xt)
            if d >= self.thr:
                return self.refine(x_in, d_in, xt, d)
            x_in, d_in = xt, d
            step *= 2.0
        self.open.add(sign)
        return bound

    def widen(self, lo: float, hi: float) -> None:
        """``grid`` more points per side, evenly out to twice the raw bound's distance from the fit (where a
        quadratic profile is at 4x the threshold): the raw bracket of a jittering model can stop just beside
        the fit, too narrow a span for a quadratic to see the smooth trend."""
        xh, span = float(self.x_hat[self.j]), self.x_hi - self.x_lo
        for sign, b in ((-1, lo), (+1, hi)):
            reach = 2.0 * abs(b - xh)
            for k in range(1, self.po.grid + 1):
                xt = float(np.clip(xh + sign * reach * k / self.po.grid, self.x_lo, self.x_hi))
                if all(abs(xt - self.p.to_x(q["value"])) > 1e-9 * span for q in self.points):
                    self.dchi2(xt)


def _smoothed(out: dict, pts: list, thr: float, level: float, p) -> None:
    """The interval from a quadratic through the noisy profile points with the Monte-Carlo-adjusted cutoff
    (stats.quadratic_profile_interval), clipped to the parameter's bounds (a clipped end is open there, as a
    raw side that never crosses); the raw one kept as "raw", its open sides as "raw_open" (lower, upper)."""
    q = stats.quadratic_profile_interval([r["value"] for r in pts], [r["delta_chi2"] for r in pts], thr, level,
                                         cap=6.0)
    out["raw"] = [out["lower"], out["upper"]]
    out["quadratic"] = q
    if q is not None:
        out["lower"] = float(max(q["lower"], p.lower))
        out["upper"] = float(min(q["upper"], p.upper))
        out["raw_open"] = [out["lower_open"], out["upper_open"]]
        out["lower_open"], out["upper_open"] = bool(q["lower"] < p.lower), bool(q["upper"] > p.upper)


def emulator_for(problem: Problem, fit: Fit, ids, reach: float = 2.5) -> CurveEmulator:
    """The profile's emulator of the coarse model over ``fit``'s parameters on the conditions ``ids``: the
    fit's own point (a cached run) and ``[profile] emulator_design`` − 1 space-filling points (at least
    parameters + 4 in all) in the box of ``reach`` Wald sd about the fit in each parameter (its whole range
    where the sd is undetermined), clipped to the bounds (:func:`~.emulator.wald_box`).  Beyond the box the
    emulator's sd grows and the profile's refits add runs where they go."""
    po, x = problem.spec.profile, np.asarray(fit.x, float)
    lo, hi = wald_box(problem, fit, ids, reach)
    em = CurveEmulator(problem, fit.params, ids, (lo, hi))
    n = max(po.emulator_design, len(fit.params) + 4)
    em.add(design_points(x, problem.evaluated(fit.params, ids), lo, hi, n, problem.spec.fit.seed))
    fill_design(em, n, "profile emulator")
    return em


def profile_interval(problem: Problem, fit: Fit, j: int, ids, level: float = 3.841, fine_forward=None,
                     emulator: CurveEmulator | None = None, correction: StrengthCorrection | None = None) -> dict:
    """Profile-likelihood interval of parameter ``j`` of ``fit`` (see the module docstring).

    Each side starts at the Wald bound and doubles its distance from the fit until the threshold is crossed,
    then the crossing is interpolated and refined (:class:`_Profile`); a side that does not cross within the
    doublings is evaluated at the parameter's bound, and where it does not cross there either it ends at that
    bound, open ("lower_open", "upper_open": the data do not bound the strength on that side).  ``fine_forward`` (the fine check models): the discretization correction is a constant
    vector estimated at the fit, so without them the profile has the coarse model's shape away from the fit;
    with them each point is corrected where it is.  ``emulator`` (:func:`emulator_for`): the refits run on it
    and each end is confirmed with real runs (:meth:`_Profile.confirm`).  Returns lower/upper (parameter
    units), the threshold, the Wald bounds, the roughness (a profile falling away from the fit: its crossings
    set by the model's jitter) and the points (value, Δχ², the others' values); with the emulator also its
    summary and checks.  ``correction``: with ``[profile] correction = "linear"``, the correction's model to
    use (default: one estimated about ``fit``, :meth:`_Profile.linear_correction`); its summary is
    "correction".  "non_monotone": the profile falls somewhere walking away from its lowest point by more
    than ``stats.MONOTONE_TOL`` of the threshold (a second minimum or jitter; flagged, not smoothed away)."""
    return _profile_run(problem, fit, j, ids, level, fine_forward, emulator, correction)[0]


def _profile_run(problem, fit, j, ids, level, fine_forward, emulator, correction) -> tuple:
    """:func:`profile_interval`'s dict and the correction model it used (None unless linear)."""
    pf = _Profile(problem, fit, j, ids, level, fine_forward, emulator, correction)
    lo, hi = pf.side(-1), pf.side(+1)
    if emulator is not None:
        lo, hi = (pf.confirm(s, b) if b not in pf.p.x_bounds else b for s, b in ((-1, lo), (+1, hi)))
    po = pf.po
    if po.smoothing == "quadratic":
        pf.widen(lo, hi)
    points = sorted(pf.points, key=lambda q: q["value"])
    rough = stats.profile_roughness([q["value"] for q in points], [q["delta_chi2"] for q in points],
                                    pf.p.from_x(pf.x_hat[j]))
    out = {"lower": float(pf.p.from_x(lo)), "upper": float(pf.p.from_x(hi)), "threshold": float(pf.thr),
           "threshold_dof": pf.dof if math.isfinite(pf.dof) else None,
           "wald": list(pf.wald), "roughness": rough, "rough": bool(rough > po.rough_tol * pf.thr),
           "points": points, "smoothing": po.smoothing,
           "reference_offset": float(pf.chi2_hat - pf.chi2_fit), "reference_chi2": float(pf.chi2_hat),
           "lower_open": -1 in pf.open, "upper_open": +1 in pf.open, "unconverged": pf.unconverged}
    low = min(points, key=lambda q: q["delta_chi2"])
    out["monotone_fall"] = stats.profile_roughness([q["value"] for q in points], [q["delta_chi2"] for q in points],
                                                   low["value"])
    out["non_monotone"] = bool(out["monotone_fall"] > stats.MONOTONE_TOL * pf.thr)
    out["correction"] = ("point" if pf.fines and pf.cm is None else "fit" if not pf.fines else pf.po.correction)
    if pf.cm is not None:
        out["correction_model"] = pf.cm.summary(problem.layout)
    if emulator is not None:
        out["emulator"] = {**emulator.summary(), "checks": pf.checks,
                           "confirmed": all(c["agrees"] for c in _last_per_side(pf.checks))}
    if po.smoothing == "quadratic":
        _smoothed(out, points, pf.thr, pf.level, pf.p)
    return out, pf.cm


def _last_per_side(checks: list) -> list:
    """The last check of each side (the one the reported end rests on)."""
    return list({c["side"]: c for c in checks}.values())
