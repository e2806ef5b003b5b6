"""``turnout diagnose``: what the simulation gets wrong — the cause(s), the extended model, the gain — or "none" / "unexplained".

The procedure (DESIGN.md §4.5; every threshold is a named constant, here or in the
module that applies it):

1. **Baseline.** The nominal scenario is simulated and compared with the measurement
   (:class:`orchestrator.inverse.objective.Target`: time alignment on the accelerometers,
   per-channel nRMSE, the objective J, the noise level of each channel estimated from
   the measurement itself). *Where* it is wrong: per group, per sleeper carrying
   sensors, and the time window holding 80 % of each channel's residual.
2. **Nuisance.** When :mod:`orchestrator.inverse.nuisance` is present, speed, time shift,
   vehicle parameters, track damping and per-channel sensor gains are fitted first
   (:func:`_nuisance`); the causes are then screened and fitted on that model and the
   nuisance estimates are reported apart, never as a track cause. Then the model's own
   time-step error (:func:`_step_error`: the reference at half its step, one run, which runs
   beside the screening), reported where a residual above the noise lives.
3. **Selection, round 1** (:func:`orchestrator.inverse.selection.select`): every
   candidate of the catalogue (each local cause on the sleepers carrying sensors and
   :data:`SENSOR_REACH` beyond them, the global ones) screened at the magnitudes of its
   grid, a dense 1-D search between them, the best re-run and fitted, all ranked by
   their BIC on the effective sample size.
3b. **Looking further** (:func:`_further`, :func:`orchestrator.inverse.selection.widen`): when
   round 1 names nothing and the residual is above the noise, the local candidates up to
   :data:`FAR_REACH` sleepers beyond the sensors are screened, confirmed and fitted too, and
   ranked with round 1's as one round, then named by the same rule. The sensors see a void a
   few sleepers beyond them through the rail's bending and the wheel's passage (measured:
   void_off_sensor 7202, a void at 25, two beyond the last instrumented sleeper 23; the truth
   removes 82 % of J; with reach 1 the answer was ``unexplained``, the best candidate a pad at
   24 removing 20 % of the explainable misfit; named at 25 with reach 3, gain 79 %). Only
   then, so a diagnosis that names a cause near the sensors pays no run for it (the default
   diagnosis would screen 8 more candidates, ~50 runs).
3c. **A channel gain against the track** (:func:`_released`): when round 1 (with step 3b) still names
   nothing and step 2 took a channel for mis-calibrated, that gain was chosen before any track cause
   was looked at, and a track effect that only that channel sees clearly looks like one (a void under
   the far end of sleeper 19 raises pressure cell A6, at the far end of sleeper 21). So the gain is
   released and round 1 judged again without it: each candidate's dense search over round 1's
   screening runs (no runs), the best confirmed and fitted (:func:`orchestrator.inverse.selection.rejudged`,
   ~10-60 runs). A cause that passes the naming rule there *and* explains the record better than the
   gain did — J lower, and its BIC on the effective sample size more than
   :data:`~orchestrator.inverse.significance.DELTA_BIC` below the reference with the gain, the gain
   counted as one fitted parameter — is named, and the gain is dropped (the nuisance notes say so).
   Otherwise the gain stands and round 1's answer with it. Why: on issue 14's field-like matrix with
   the drawn acquisition filter, void_sensor 7202 and void_sensor+mismatch 7404 (a void at 19, its
   largest gap under the far end) had A6 taken for mis-calibrated (gains 1.30 and 1.17) and answered
   ``unexplained`` and ``none``. A true gain fault is not at risk in the same way: a gain explains its
   channel to the noise, where a track cause moves its neighbours too.
4. **Naming** (:func:`_pick`): the best-ranked candidate that passes the rule of
   :mod:`orchestrator.inverse.significance` — significant on the effective sample size,
   removes at least a quarter of the explainable misfit, never makes the fit worse, and
   holds with any sensor group held out. Candidates within ΔBIC 10 of it on the
   effective sample size cannot be told apart from it: its ambiguity set. The ranking
   (BIC: channels weighted by their effective samples) and the share (J: groups weighted
   equally) can disagree, so the named one may rank more than ΔBIC 10 below a candidate
   that failed only the share (measured: right in two_void_pad 7000, where the void
   removed 62 % of J and the better-ranked pad 15 %; wrong in void_sensor+mismatch 7101,
   where the true void at 19 removed 23 % of the explainable misfit and a void at 18,
   ranked ΔBIC 75 below it, 29 %: the floor of :mod:`orchestrator.inverse.significance`,
   "Known limits"; that case was measured while the nuisance fit took the void's rise of
   pressure cell A6 for A6's gain; since the gain must leave its channel at the noise level
   (:mod:`orchestrator.inverse.nuisance`, stage 2) the void at 19 is named, gain 61 %).
   Where the two criteria disagree between sites of the *same* cause, neither is trusted
   over the other: the candidates of the named one's cause that rank
   above it and fail only the share join its ambiguity set (:func:`_preferred`;
   ``ambiguity.ranked_above`` says which), so the answer is "a void at 18 or 19", not a
   confident wrong sleeper. A better-ranked candidate of *another* cause does not: a
   cause that removes a quarter of the explainable misfit is not set aside for one that
   does not.
4b. **Shift and speed again** (:func:`_moved`): with a cause named and before round 2, the time shift
   is aligned again on that model's run (stage 1 aligned it on the nominal run, and a worn nose moves
   the impact's instant: :func:`_aligned_again`), then the speed found again from the data on it (as
   step 5c does, :func:`_speed_between`); each is kept when it fits better by step 5c's rule
   (:func:`_lower`), and round 2 (and step 5b) then runs at that shift and speed. Measured on issue 14's
   field-like two_nose_void 7606: the void beside the worn nose removed 22 % of the explainable misfit at
   stage 1's alignment (not named) and 29 % after it (named, gain 85.6 %).
5. **Round 2, forward selection** (:func:`_second_round`): with a cause named, the
   :data:`SECOND_ROUND` candidates whose round-1 screening signals, added as a change to
   the extended model's, fit best (no runs) are screened for real on top of the
   extended model and the :data:`SECOND_CONFIRM` best of them fitted, and a second
   cause is named by the same rule relative to it (at most :data:`MAX_CAUSES`), each
   with its own gain. The first cause stays at its round-1 values. Superposing round 1's
   screening is first order, so when the residual the first cause leaves is above the noise,
   round 2 also screens (:func:`_at_the_residual`), each only when not already chosen:

   * the local candidates at the sleeper nearest the residual's peak in time
     (:func:`orchestrator.inverse.significance.locate`, on the extended model after step 4b;
     since session 35): an effect under the impact interacts with the first cause (two_nose_void
     7505: a void at 23 ranked 7th by superposition, named when run on the worn-nose model);
   * the local candidates at the sleeper of the residual's loudest channel
     (:func:`_loudest_sleeper`; session 38): the wheel's place at the peak need not be the
     effect's (two_nose_void 8010: the peak at 24, the void at 22 under channel B4);
   * the global causes no named cause has taken (the impact angle, the bed's and every pad's
     stiffness; session 39): they change every channel, so they have no site where the residual
     lives, and their round-1 screening superposes badly on a model with the first cause
     (two_nose_void 8414: the nose removed 38 % of the explainable misfit on the void's model and
     was never among the four superposition ranked).

   Each was measured on issue 14's field-like matrix before it landed: answers it changed,
   runs it cost (+1.1 to +1.2 % each), out-of-sample seeds after it (benchmarks/RESULTS.md,
   sessions 35, 38 and 39). Known limit: two effects that interact strongly are missed when
   the first cause, fitted alone, takes a shape that stands in for the second (measured on
   two_void_pad 7101, a void beside a soft pad: the pad then *raised* J on the void's model; that
   case is named since session 38's noise floor, the mechanism stands); refitting the
   first cause with each second candidate (stepwise regression's refit, ~70 runs a void) would
   address it and is not done. two_nose_void 7808 (a void at 22 beside a worn nose, its loudest
   channel on 21) is still missed; screening every free local candidate in round 2 named a void
   at 20 there at +55 % runs, not landed (session 39).
5b. **Backfitting** (:func:`_backfit`): once a second cause is named, each named cause's
   parameters are fitted again (all of them, from their current values) on the model with
   the other at its latest values, first cause first — one pass of backfitting, so the
   extended model does not keep what the first cause took up of the second effect when it
   was fitted alone, nor the second's fit to that. A refit is kept when it fits better
   by step 5c's rule (:func:`_lower`; until 2026-11-28 both chi-square and J had to fall: on the
   14 two-effect field-like cases one more refit is kept, its gain 0.005 points lower, the rest
   unchanged); the named entry then carries the refitted parameters, its intervals at them
   (given the other cause as it was then) and the values it was named with under
   ``evidence.refit``. Its naming evidence and per-cause gain stay those of its round.
5c. **Nuisance again** (:func:`_nuisance_again`,
   :func:`orchestrator.inverse.nuisance.refit_with_causes`): with a cause named, the
   vehicle and damping values and the time shift are fitted once more (a Jacobian and three
   Gauss-Newton steps, ~10 runs; the speed stays step 2's or step 4b's) on the model with the named
   causes (from step 2's values, in its box, with its acceptance rule; the causes'
   parameters stay): step 2 runs before any cause, so a value that
   can imitate part of a track effect took it up, or was refused, pressed against its box
   by it. Then the speed: stage 1's warp again, on the extended model (a track effect that changes
   the signals' shape moves the warp of the nominal run: a global pad or a worn nose beside a
   vehicle mismatch left it 1.5 % and 3.9 % off), with a run at the new speed when it asks for
   more than 0.1 % (:func:`orchestrator.inverse.nuisance.speed_again`). And the joint refit
   (:func:`orchestrator.inverse.nuisance.refit_jointly`): the same steps with the named causes'
   parameters free too (~15 runs for a void), since a cause fitted on step 2's model and a vehicle
   value that took up part of it are coupled and one pass of backfitting leaves both short
   (measured, RESULTS session 29: void_off_sensor 7303, the wheelset mass at 1882 kg for a true
   1500; J 0.0524 -> 0.0231 by the refit, 0.0204 jointly, the truth's own 0.0207). Three paths are
   tried, side by side: the refit and then the speed on the refit's model, the joint refit and then
   the speed on its model, and the speed on the model with the named causes as they were. Kept: the point of least J among those that fit better
   than that model (:func:`_lower`: J falls, and the chi-square *or* the deviance on the effective
   sample size falls with it). The reported nuisance estimates and the extended model are then
   that point's. Why both paths and this rule (RESULTS 2026-11-28, session 27, leads 1-2): before,
   the refit was kept only when both chi-square and J fell, and the speed then on whichever model
   that left. The chi-square is dominated by the reconstructed displacements, whose noise sigma is
   read 3-50x low (:mod:`orchestrator.inverse.significance`, "Known limits"), so refits that lowered
   J by up to 37 % were refused (the deviance, floored at each channel's noise level and counted on
   N_eff, is scale-free per channel and fell); keeping them under a looser rule but on one path moved
   the gains either way (-7.5 to +4.1 points), because a refit kept set another start for the speed.
   Here the old rule's point is always among those tried and better, so from a given model J can
   only come out lower. These runs go beside those of step 6's intervals
   (:func:`_named_and_nuisance_again`).
5d. **Causes again** (:func:`_causes_again`): when step 5c moved the nuisance values, each named
   one-parameter cause (a global or local pad, the bed, the impact angle) is fitted again on its
   model, from its value, by the finest stage of its fit, and kept by step 5c's rule; its entry
   then carries the new value and its intervals there, and ``evidence.refit_nuisance`` the value
   before. The cause had been fitted with stage 3's values, and its optimum moves with them
   (measured: pad_global 7303, the scale fitted 3.83 for a true 4.16; with step 5c's values J's
   minimum lies at 4.1-4.16). Voids (six gaps, ~50 runs a fit) are not fitted again. One pass:
   the nuisance values are not fitted again after it. When step 5c kept the joint refit, each
   cause starts from its joint value, and a cause the joint refit moved (a void too) carries that
   value and its intervals there even when no refit here is kept.
6. **Answer** (:func:`_answer`): ``named`` (with each cause's 90 % intervals,
   identifiability and which sensors would pin it:
   :mod:`orchestrator.inverse.uncertainty`); else ``none`` when the residual is at the
   noise level, with what the record resolves: per candidate of round 1, the least effect that would
   have lifted the residual above the noise, from round 1's screening runs (no runs;
   :mod:`orchestrator.inverse.resolution`); else ``unexplained`` with where it lives (channels, time window, the
   sleeper nearest the wheel then, frequency band:
   :func:`orchestrator.inverse.significance.locate`).
7. **Extended model and gain.** The named causes are added to the scenario
   (``extended.yaml``); gain = 1 - J_after / J_before, per channel and in total; for
   further measured passages at other speeds (``--validate FILE@SPEED``) the same
   before/after comparison without refitting.

A diagnosis never ends in a traceback from a variant: a run that stops early, a
non-finite signal or a comparison window outside the record drops that variant with a
logged reason (:func:`orchestrator.inverse.screening.checked_comparison`); the answer
lists them (``dropped``). The nominal run itself failing is a :class:`UserInputError`.

The diagnosis sees only the scenario and the measurement files: the catalogue, the
grids and the thresholds are fixed, the same for every measurement.

:func:`diagnose` runs these steps as a sequence of stages (one function each, from
:func:`_read_inputs` to :func:`_write_outputs`) and returns the typed result,
:class:`orchestrator.inverse.diagnosis.Diagnosis`, whose ``to_json()`` is
``diagnosis.json``; the report is :mod:`orchestrator.inverse.diagnose_report`.
"""
from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from orchestrator.cosim.sensing import variant_for_speed
from orchestrator.inputs.causes import CATALOGUE, Candidate, candidates, kind_of
from orchestrator.inputs.errors import UserInputError
from orchestrator.inverse.diagnosis import Answer, Baseline, CauseFit, Diagnosis, Gain, Passage
from orchestrator.inverse.jsonable import numpy_default
from orchestrator.inverse.nuisance import NuisanceFit, widen_speed_for_step
from orchestrator.inverse.objective import Comparison, Target
from orchestrator.inverse.resolution import resolution, summary
from orchestrator.inverse.screening import Evaluated, Pool, checked_comparison
from orchestrator.inverse.selection import (CONFIRM, FINE_MAX_NFEV, FIT, CauseFitter, Round, cause_stages, rejudged,
                                             select, side_by_side, superposed_ranking, widen)
from orchestrator.inverse.significance import (CV_TOL, DELTA_BIC, LOUD_FACTOR, MIN_SHARE, NONE_MARGIN, Evidence,
                                               assess, at_noise_level, bic_eff, channel_neff, deviance, locate,
                                               step_error)
from track.sensors import sleeper_of, sleepers_of

SENSOR_REACH = 1     # local causes on the sleepers carrying sensors +- this many (an effect just beyond them)
FAR_REACH = 3        # ... and +- this many when round 1 names nothing above the noise (step 3b)
MAX_CAUSES = 2       # causes named at most (forward selection)
SECOND_ROUND = 4     # candidates of round 1 (next best) screened again on top of the first named cause, ...
SECOND_CONFIRM = 2   # ... of which this many are re-run and fitted
SIGNAL_STEP_ORDER = 1   # order of the model's time-step error in the compared signals (_step_words): band-limited,
                        # J between successive halvings 0.034, 0.021, 0.011 (ratios 1.6, 1.9: about first order;
                        # benchmarks/RESULTS.md, session 32)


def _parse_validate(texts) -> list[tuple[Path, float]]:
    """``--validate`` texts ``FILE@SPEED`` as (path, speed [m/s]); :class:`UserInputError` if malformed."""
    out = []
    for text in texts or ():
        path, sep, speed = str(text).rpartition("@")
        try:
            v = float(speed)
        except ValueError:
            v = float("nan")
        if not sep or not path or not (v > 0 and math.isfinite(v)):
            raise UserInputError(f"--validate {text!r}: give FILE@SPEED with the speed in m/s, e.g. pass2.csv@27.78")
        out.append((Path(path), v))
    return out


def _where(cmp: Comparison, sensors) -> dict:
    """Where the simulation is wrong: groups, sleepers, time windows of the worst channels."""
    by_sleeper: dict[int, list[float]] = {}
    for s in sensors:
        if s.id in cmp.channels and (k := sleeper_of(s.body)) is not None:
            by_sleeper.setdefault(k, []).append(cmp.channels[s.id]["nrmse"])
    worst = sorted(cmp.channels, key=lambda k: -cmp.channels[k]["nrmse"])[:5]
    return {"groups": dict(sorted(cmp.groups.items(), key=lambda kv: -kv[1])),
            "sleepers": {str(k): float(np.mean(v)) for k, v in sorted(by_sleeper.items())},
            "worst_channels": [{"id": k, "nrmse": cmp.channels[k]["nrmse"], "t_peak": cmp.channels[k]["t_peak"],
                                "window": cmp.channels[k]["window"]} for k in worst]}


# ------------------------------------------------------------------------------------ stages

@dataclass
class _Inputs:
    """What the stages of a diagnosis read: the nominal scenario, its sensors, the measurements, the candidates.

    Attributes
    ----------
    scenario_path, measured_path
        As given to :func:`diagnose`.
    out_dir : Path
    scenario : Scenario
        The nominal scenario (:attr:`raw` is its raw dict).
    layout : SensorLayout
    sensors : list
        The layout's sensors resolved on the nominal track model.
    target : Target
        The measured passage.
    validations : list of (Target, Path, float)
        Further passages: their target, file and speed [m/s].
    cands : list of Candidate
        The catalogue's candidates at the sensors (and :data:`SENSOR_REACH` beyond).
    sleeper_x : ndarray
        Track coordinate of every sleeper [m], by index (where an unexplained residual lives).
    x_start : float
        The front wheelset's position at t = 0 [m]: ``simulation.x_start`` or the job's choice
        when it is null (:func:`orchestrator.cosim.passage.start_position`).
    """

    scenario_path: object
    measured_path: object
    out_dir: Path
    scenario: object
    layout: object
    sensors: list
    target: Target
    validations: list
    cands: list
    sleeper_x: np.ndarray
    x_start: float
    looked_further: bool = False   # step 3b ran: ``cands`` holds the far candidates too

    @property
    def raw0(self) -> dict:
        """The nominal scenario's raw dict."""
        return self.scenario.raw


def _read_inputs(scenario_path, measured_path, out_dir, validate) -> _Inputs:
    """Read and check everything before any run.

    Input: :func:`diagnose`'s paths and ``--validate`` texts. Output: the :class:`_Inputs`
    (``out_dir`` is created). Raises :class:`UserInputError` on bad input.
    """
    from orchestrator.cosim.passage import start_position
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inputs.sensor_layout import layout_of, resolve
    from orchestrator.inputs.track_model import track_model

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    validations = _parse_validate(validate)
    scenario = load_scenario(scenario_path)
    layout = layout_of(scenario)
    model = track_model(scenario.track)
    sensors = resolve(layout, model)
    target = Target.read(measured_path, layout)
    sim_rate = 1.0 / scenario.simulation.output_step
    if sim_rate < 2.0 * target.measured.rate * (1 - 1e-9):
        raise UserInputError(f"{measured_path}: sampled at {target.measured.rate:g} Hz; the simulation's output step "
                             f"({scenario.simulation.output_step:g} s) must be at most half the sampling interval "
                             f"(simulation.output_step <= {0.5 / target.measured.rate:.3g} s)")
    val_targets = [(Target.read(p, layout), p, v) for p, v in validations]
    cands = candidates(sleepers_of(sensors), len(model.layout.sleepers), SENSOR_REACH)
    sleeper_x = np.array([s.x for s in model.layout.sleepers], float)
    x_start = start_position(scenario, model.layout)
    return _Inputs(scenario_path, measured_path, out_dir, scenario, layout, sensors, target, val_targets, cands,
                   sleeper_x, x_start)


def _baseline(pool: Pool, inp: _Inputs) -> tuple[Evaluated, Baseline]:
    """Step 1: the nominal run.

    Input: the pool, the inputs. Output: the nominal model's :class:`Evaluated` and its
    :class:`Baseline`, which is written to ``baseline.json`` at once (so a diagnosis that
    fails later keeps it). Aligns ``inp.target`` in time on the nominal run. Raises
    :class:`UserInputError` when the nominal run cannot be compared with the measurement.
    """
    base_run = pool.map([inp.raw0])[0]
    if base_run.error:
        raise UserInputError(f"{inp.scenario_path}: the nominal run stopped early: {base_run.error}")
    inp.target.align_to(base_run.t, base_run.signals)
    cmp, why = checked_comparison(inp.target, base_run)
    if cmp is None:
        raise UserInputError(f"{inp.measured_path}: cannot be compared with the nominal run: {why}")
    outside = sum(int((~np.isfinite(y)).sum()) for y in cmp.simulated.values())
    if outside:
        total = sum(y.size for y in cmp.simulated.values())
        pool.drop("samples of the record", "baseline", f"{outside} of {total} channel samples lie outside the "
                  f"simulated window: masked in every comparison")
    base = Evaluated(Candidate("none"), np.zeros(0), cmp, 0, "nominal")
    text = json.dumps({**base.cmp.summary(), "bic": base.bic(), "where": _where(base.cmp, inp.sensors),
                       "noise_sigma": inp.target.sigma}, indent=1, default=numpy_default)
    (inp.out_dir / "baseline.json").write_text(text)
    return base, Baseline.from_json(json.loads(text))


def _nuisance(pool: Pool, inp: _Inputs, base: Evaluated) -> tuple[dict, Evaluated, NuisanceFit]:
    """Step 2: the nuisance parameters, fitted before any cause (:mod:`orchestrator.inverse.nuisance`).

    Output: the reference scenario the causes are screened on (the nominal one with the
    nuisance estimates), its evaluation, and the nuisance estimates. Sets the channel
    gains on ``inp.target``.
    """
    from orchestrator.inverse.nuisance import fit_nuisance

    nz = fit_nuisance(pool, inp.target, inp.raw0, base.cmp)
    return nz.raw, Evaluated(Candidate("none"), np.zeros(0), nz.cmp, 0, "nominal"), nz


def _lower(cmp: Comparison, start: Comparison, sigma: dict) -> bool:
    """Step 5c's rule: ``cmp`` fits better than ``start`` — J falls, and the chi-square or the deviance on the
    effective sample size (:func:`orchestrator.inverse.significance.deviance`, each channel's variance floored at
    its noise level, both weighed by ``cmp``'s N_eff as the naming rule weighs a cause) falls with it (module doc)."""
    if not cmp.objective < start.objective:
        return False
    if cmp.chi2 < start.chi2:
        return True
    neff = channel_neff(cmp)
    return deviance(cmp, sigma, neff) < deviance(start, sigma, neff)


def _nuisance_again(pool: Pool, inp: _Inputs, nz: NuisanceFit, ext_raw: dict,
                    final: Comparison, named: Sequence[_Named] = ()) -> tuple[NuisanceFit, dict, Comparison,
                                                                           list | None]:
    """Step 5c: the nuisance values fitted again on the model with the named causes, and its speed found
    again from the data — every path tried, the best point kept (module doc).

    The points: the refit (:func:`orchestrator.inverse.nuisance.refit_with_causes`), the joint refit of the
    nuisance values with the ``named`` causes' parameters (:func:`orchestrator.inverse.nuisance.refit_jointly`),
    the speed found again on either's model and on the model given
    (:func:`orchestrator.inverse.nuisance.speed_again`), the three paths side by side. Kept: the one of least
    J among those that fit better than the model given (:func:`_lower`). Output: the nuisance estimates, the
    extended raw scenario and its comparison (those given when no point fits better), and the named causes'
    values when the point kept is the joint refit's (else None); the estimates' notes say what each path gave
    and which was kept.
    """
    from orchestrator.inverse.nuisance import refit_jointly, refit_with_causes, speed_again

    own = replace(inp.target, shift=final.shift)   # the extended model's alignment (step 4b may have moved it)

    def refit_path() -> tuple[list, int]:
        mine = copy.deepcopy(nz)
        got = refit_with_causes(pool, own, mine, ext_raw, final)
        if got is None:
            return [], mine.runs - nz.runs
        fit, cmp = got
        points = [("the refit", fit, fit.raw, cmp, None)]
        sp = speed_again(pool, inp.target, copy.deepcopy(fit), fit.raw, cmp)
        if sp is not None:
            points.append(("the refit, then the speed", *sp, None))
        return points, points[-1][1].runs - nz.runs

    def joint_path() -> tuple[list, int]:
        mine = copy.deepcopy(nz)
        causes = [(kind_of(n.e.candidate), n.e.candidate.sleeper, n.values) for n in named]
        got = refit_jointly(pool, own, mine, causes, final) if causes else None
        if got is None:
            return [], mine.runs - nz.runs
        fit, cmp, values = got
        points = [("the joint refit", fit, fit.raw, cmp, values)]
        sp = speed_again(pool, inp.target, copy.deepcopy(fit), fit.raw, cmp)
        if sp is not None:
            points.append(("the joint refit, then the speed", *sp, values))
        return points, points[-1][1].runs - nz.runs

    def speed_path() -> tuple[list, int]:
        mine = copy.deepcopy(nz)
        sp = speed_again(pool, inp.target, mine, ext_raw, final)
        return ([("the speed", *sp, None)] if sp is not None else []), mine.runs - nz.runs

    got = side_by_side(pool, {"refit": refit_path, "joint": joint_path, "speed": speed_path})
    points = got["refit"][0] + got["joint"][0] + got["speed"][0]
    runs = nz.runs + got["refit"][1] + got["joint"][1] + got["speed"][1]
    better = [p for p in points if _lower(p[3], final, inp.target.sigma)]
    tried = "; ".join(f"{name}: J {final.objective:.4g} -> {cmp.objective:.4g}, chi-square {final.chi2:.4g} -> "
                      f"{cmp.chi2:.4g}" for name, _, _, cmp, _ in points)
    if not better:
        nz.runs = runs
        if points:
            nz.notes.append(f"nuisance again with the named causes ({tried}): none fits better; stage 3's values "
                            "and the speed stand")
        return nz, ext_raw, final, None
    name, fit, raw, cmp, values = min(better, key=lambda p: p[3].objective)
    fit.runs = runs
    fit.notes.append(f"nuisance again with the named causes ({tried}): kept {name}")
    return fit, raw, cmp, values


def _causes_again(pool: Pool, inp: _Inputs, named: list[_Named], entries: list[CauseFit], nz: NuisanceFit,
                  ext_raw: dict, final: Comparison) -> tuple[dict, Comparison]:
    """Step 5d: each named one-parameter cause fitted again on the model of step 5c, when step 5c moved it;
    a cause step 5c's joint refit moved takes its values from there.

    The causes were fitted with stage 3's nuisance values; step 5c moves those, and the cause's optimum
    moves with them (module doc, 5d). From its current value (the joint refit's, when step 5c kept that),
    on the extended model with step 5c's values and time shift, the finest stage of the cause's fit
    (:meth:`orchestrator.inverse.selection.CauseFitter.fit`); kept by step 5c's rule (:func:`_lower`). A
    void's six gaps are not fitted again here (~50 runs for at most 1.6 points of gain: RESULTS, session 28).
    A cause whose values moved — by the joint refit, this fit, or both — has its entry's parameters set, its
    intervals taken at them (on this model) and ``evidence.refit_nuisance`` (the values before, J before and
    after). Output: the extended raw scenario and its comparison.
    """
    from orchestrator.inverse.uncertainty import cause_uncertainty

    if nz.refit is None and nz.speed_again is None:
        return ext_raw, final
    own = replace(inp.target, shift=final.shift)
    for n, entry in zip(named, entries):
        c, kind = n.e.candidate, kind_of(n.e.candidate)
        before = n.values
        values = n.joint if n.joint is not None else before
        start = Evaluated(c, values, final, n.e.k, "fitted")
        fitter = CauseFitter(pool, own, ext_raw, start, final)
        fitter.known(values, final)
        got = None
        if len(kind.names) == 1:
            pool.expect(2 * FINE_MAX_NFEV)
            got = fitter.fit(start, slice(0, None), FINE_MAX_NFEV)
            got = got if _lower(got.cmp, final, inp.target.sigma) else None
        if got is None and n.joint is None:
            continue
        was = n.joint_from if n.joint is not None else final
        new, cmp = (got.values, got.cmp) if got is not None else (values, final)
        reason = {(True, False): "fitted jointly with the nuisance values in step 5c",
                  (True, True): "fitted jointly with the nuisance values in step 5c, then again alone on that model",
                  (False, True): "fitted again on the model with the nuisance values of step 5c"}[
            (n.joint is not None, got is not None)]
        entry.evidence["refit_nuisance"] = {
            "parameters_before": kind.parameters(before), "objective_before": was.objective,
            "objective_after": cmp.objective, "chi2_before": was.chi2, "chi2_after": cmp.chi2,
            "runs": len(fitter.cache) - 1, "reason": reason}
        entry.parameters = kind.parameters(new)
        entry.uncertainty = cause_uncertainty(fitter, new, n.evidence.n_eff)
        if got is not None:
            ext_raw, final = kind.apply(ext_raw, c.sleeper, got.values), got.cmp
    return ext_raw, final


def _named_and_nuisance_again(pool: Pool, inp: _Inputs, named: list[_Named], nz: NuisanceFit, ext_raw: dict,
                              final: Comparison) -> tuple[list[CauseFit], NuisanceFit, dict, Comparison]:
    """The named causes' entries with their intervals (step 6, :func:`_named_entry`) and step 5c
    (:func:`_nuisance_again`), side by side (:func:`orchestrator.inverse.selection.side_by_side`).

    Neither needs the other: a cause's intervals are taken on the model it was named on
    (stage 3's nuisance values), and step 5c keeps the causes' values. Step 5c's Gauss-Newton
    steps are one run each and would leave the second of two workers idle (measured on the
    default diagnosis: 2.5 worker-seconds of its 4.4 s); the intervals' runs fill it.
    Output: the entries, then what :func:`_nuisance_again` returns.
    """
    local = [c.sleeper for c in inp.cands if c.sleeper is not None]
    reach = (min(local), max(local)) if local else (-1, -1)
    calls = {"entries": lambda: [_named_entry(n, i + 1, reach) for i, n in enumerate(named)]}
    if named:
        calls["again"] = lambda: _nuisance_again(pool, inp, nz, ext_raw, final, named)
    got = side_by_side(pool, calls)
    nz_new, raw_new, final_new, joint = got.get("again", (nz, ext_raw, final, None))
    for n, v in zip(named, joint or ()):
        n.joint, n.joint_from = np.asarray(v, float), final
    return got["entries"], nz_new, raw_new, final_new


def _step_error(pool: Pool, inp: _Inputs, ref_raw: dict, ref: Evaluated) -> Callable[[], dict | None]:
    """Step 2b: the model's own time-step error (:func:`orchestrator.inverse.significance.step_error`).

    One run: the reference at half its time step (same output step), started now and waited for
    when the answer needs it (the function returned), so that it runs beside the screening.
    Output of that function: the step error's JSON (``step`` [s], ``objective``, ``groups``,
    ``channels``; ``speed_ratio`` and ``speed_bias``: what the step does to the fitted speed,
    :func:`orchestrator.inverse.nuisance.speed_step_bias`) or None when that run cannot be
    compared (dropped with its reason).
    """
    fine_raw = copy.deepcopy(ref_raw)
    fine_raw["simulation"]["step"] = 0.5 * float(ref_raw["simulation"]["step"])
    pool.expect(1)
    pending = pool.submit([fine_raw])
    gains = dict(inp.target.gains)
    runs: list = []   # the run, once waited for: the function is called after round 1 and again at the end

    def result() -> dict | None:
        from orchestrator.inverse.nuisance import speed_step_bias

        if not runs:
            runs.extend(pending())
        # step 3c may have released a channel gain since: the reference compared as the half-step run is
        ref_cmp = ref.cmp if inp.target.gains == gains else inp.target.score(ref.cmp.simulated)
        cmp, why = checked_comparison(inp.target, runs[0], ref_cmp)
        if cmp is None:
            if not any(d.get("stage") == "step error" for d in pool.dropped):   # dropped once
                pool.drop("the reference at half its time step", "step error", why)
            return None
        a, bias = speed_step_bias(inp.target, ref_cmp, cmp)
        return {"step": float(ref_raw["simulation"]["step"]), **step_error(ref_cmp, cmp, inp.target),
                "speed_ratio": a, "speed_bias": bias}

    return result


def _pick(rd: Round, target: Target) -> tuple[Evaluated | None, Evidence | None, dict]:
    """Step 4: the best-ranked candidate of a round that passes the rule, its evidence, and every tried one's.

    Output: (the named candidate or None, its evidence (or the best one's when none
    passes), candidate -> evidence of the fitted and confirmed candidates).
    """
    tried = {e.candidate: assess(e.cmp, e.k, rd.reference.cmp, rd.k_ref, target) for e in rd.real}
    for e in rd.real:
        if tried[e.candidate].passes:
            return e, tried[e.candidate], tried
    return None, (tried[rd.real[0].candidate] if rd.real else None), tried


def _same_site(a: Candidate, b: Candidate) -> bool:
    """The two candidates set the same scenario entry (one would overwrite the other)."""
    return kind_of(a).scenario_key(a.sleeper) == kind_of(b).scenario_key(b.sleeper) and a.sleeper == b.sleeper


@dataclass
class _Named:
    """A named cause: its evaluation, evidence, round, and the reference scenario with it added.

    ``preferred``: the candidates of the same cause that rank above it and fail only the
    share (:func:`_preferred`).
    """

    e: Evaluated
    evidence: Evidence
    round: Round
    raw: dict
    preferred: list = field(default_factory=list)
    refit: Evaluated | None = None       # step 5b: refitted with the other cause (None: not refitted / no better)
    refit_fitter: CauseFitter | None = None
    refit_from: float | None = None      # J of the extended model before this refit
    joint: np.ndarray | None = None      # step 5c: its values from the joint refit with the nuisance values (kept)
    joint_from: Comparison | None = None  # the extended model's comparison before step 5c
    moved: Comparison | None = None      # step 4b: ``raw``'s comparison at the shift and speed found again on it

    @property
    def values(self) -> np.ndarray:
        """Its values as step 5b left them (the refit's, when one was kept)."""
        return self.refit.values if self.refit is not None else self.e.values


def _preferred(rd: Round, pick: Evaluated, tried: dict) -> list[Candidate]:
    """Step 4: the candidates of the named one's cause that rank above it (BIC on N_eff) and fail only the share.

    The ranking and the share disagree about them (module doc, 4.): the data prefer them
    statistically, the share the named one. The named cause's ambiguity set holds them
    too (:func:`_named_entry`), so a site the ranking prefers is never dropped silently.
    """
    above = rd.real[:rd.real.index(pick)]
    return [o.candidate for o in above
            if o.candidate.cause == pick.candidate.cause and tried[o.candidate].fails_only_share]


def _released(pool: Pool, inp: _Inputs, raw: dict, ref: Evaluated, nz: NuisanceFit,
              rd: Round) -> tuple[Evaluated, Round] | None:
    """Step 3c (module doc): round 1, which named nothing, judged again with each channel gain of step 2
    released in turn; the first release under which a cause is named and explains the record better than
    the gain did is kept. Output: the reference's evaluation and the round judged again (``inp.target``,
    ``nz``'s gains, comparison and notes changed), or None (nothing changed)."""
    for k in sorted(inp.target.gains):
        g = inp.target.gains[k]
        target = replace(inp.target, gains={j: v for j, v in inp.target.gains.items() if j != k})
        bare = Evaluated(ref.candidate, ref.values, target.score(ref.cmp.simulated), ref.k, ref.stage)
        again = rejudged(pool, target, raw, bare, rd)
        pick, ev, _ = _pick(again, target)
        if pick is None:
            why = "; ".join(ev.reasons) if ev is not None else "no candidate could be evaluated"
            nz.notes.append(f"channel {k}: with its gain released no cause is named (the best {why}): the gain "
                            "stands")
            continue
        neff = channel_neff(pick.cmp)
        b_cause = bic_eff(pick.cmp, target.sigma, neff, pick.k)
        b_gain = bic_eff(ref.cmp, inp.target.sigma, neff, 1)
        words = (f"{pick.candidate.label}: J {pick.cmp.objective:.4g}, BIC on N_eff {b_cause:.1f}; the gain "
                 f"{g:.3f}: J {ref.cmp.objective:.4g}, BIC {b_gain:.1f}")
        if not (pick.cmp.objective < ref.cmp.objective and b_cause < b_gain - DELTA_BIC):
            nz.notes.append(f"channel {k}: with its gain released, {words}: the gain explains the record as "
                            "well or better and stands")
            continue
        inp.target = target
        del nz.channel_gains[k]
        nz.cmp = bare.cmp
        nz.notes.append(f"channel {k}: gain {g:.3f} released (step 3c): a track cause explains the record better "
                        f"({words})")
        return bare, again
    return None


def _step_floor(step_json: dict | None) -> dict:
    """Channel id -> the model's own time-step error against the converged model (the half-step difference
    extrapolated at order :data:`SIGNAL_STEP_ORDER`, as :func:`_step_words` does): ``Target.floor``."""
    if step_json is None:
        return {}
    return {k: _converged(v) for k, v in step_json["channels"].items()}


def _converged(half_step_difference: float) -> float:
    """Richardson's extrapolation at order :data:`SIGNAL_STEP_ORDER`: the error against the converged model from
    the difference to the run at half the step, ``d x 2^p / (2^p - 1)`` (twice it at first order)."""
    p = SIGNAL_STEP_ORDER
    return half_step_difference * 2.0 ** p / (2.0 ** p - 1.0)


def _rounds(pool: Pool, inp: _Inputs, ref_raw: dict, ref: Evaluated, nz: NuisanceFit,
            step_err: Callable[[], dict | None] = lambda: None) -> tuple[list[_Named], list[Round], dict,
                                                                       NuisanceFit, dict, Evaluated]:
    """Steps 3-5: round 1 over all candidates, then forward selection (module doc), with the time shift and
    the speed found again on the first named cause's model before round 2 (step 4b, :func:`_moved`).

    Output: the named causes (in order), the rounds, candidate -> evidence of every
    candidate tried for naming (per round: label keys ``round:label``), the nuisance estimates (``nz``,
    updated by step 4b), the reference scenario at their speed, and the reference's evaluation (``ref``,
    or compared anew when step 3c released a channel gain).
    """
    named: list[_Named] = []
    raw, target = ref_raw, inp.target
    rounds = [select(pool, target, raw, ref, 0, inp.cands)]
    target.floor = _step_floor(step_err())   # the share's floor (step 4), once the half-step run is in
    evidence = {}
    released = False
    while True:
        rd = rounds[-1]
        pick, ev, tried = _pick(rd, target)
        far = _further(inp, ref) if pick is None and len(rounds) == 1 else []
        if far:   # step 3b: round 1 looks further
            rounds[0] = widen(pool, target, raw, rd, far)
            inp.cands, inp.looked_further = inp.cands + far, True
            continue
        if pick is None and len(rounds) == 1 and not released and inp.target.gains:   # step 3c
            released = True
            got = _released(pool, inp, raw, ref, nz, rd)
            if got is not None:
                ref, rounds[0] = got
                target = inp.target
                continue
        evidence.update({(len(rounds), c): v for c, v in tried.items()})
        if pick is None:
            break
        c = pick.candidate
        raw = kind_of(c).apply(raw, c.sleeper, pick.values)
        named.append(_Named(pick, ev, rd, raw, _preferred(rd, pick, tried)))
        if len(named) >= MAX_CAUSES:
            break
        nxt = _second_round(target, rounds[0], named)
        if not nxt:
            break
        target, nz, raw, cmp = _moved(pool, target, nz, raw, pick.cmp, f"{c.label}, before round 2")
        nxt = nxt + _at_the_residual(inp, target, cmp, float(raw["vehicle"]["speed"]), named, nxt)
        start = pick if cmp is pick.cmp else Evaluated(c, pick.values, cmp, pick.k, pick.stage)
        named[-1].raw, named[-1].moved, ref_raw = raw, (None if cmp is pick.cmp else cmp), nz.raw
        rounds.append(select(pool, target, raw, start, sum(n.e.k for n in named), nxt, SECOND_CONFIRM))
    if len(named) == 2:
        _backfit(pool, target, ref_raw, ref, named)
    return named, rounds, evidence, nz, ref_raw, ref


def _aligned_again(pool: Pool, target: Target, nz: NuisanceFit, raw: dict, cmp: Comparison,
                   label: str) -> tuple[Target, Comparison]:
    """Step 4b: the time shift aligned again (:meth:`orchestrator.inverse.objective.Target.align_to`, on the
    accelerometers) on the model with the first named cause (``raw``, compared as ``cmp``), before round 2;
    one run.

    The shift is aligned once, on the nominal run (stage 1), and held for every variant: a track's stiffness
    or a void hardly moves the impact's instant. A worn nose moves it, as it moves where the wheel lands on
    the nose; round 2 then weighs its candidates against a reference misaligned by it, and a second cause
    removes a smaller share of that misfit than of the one it explains. Measured on issue 14's field-like
    two_nose_void 7606 (a worn nose and a 0.8 mm void at 23; the truth's speed): J of the worn nose alone
    0.0962 aligned on the nominal run, 0.0843 aligned on its own run; with the void 0.0722 and 0.0581, the
    void's share of the explainable misfit 0.44 and 0.60 (noise J 0.041).

    Kept when it fits better by step 5c's rule (:func:`_lower`); then ``nz.shift`` is the new shift and a
    note (naming ``label``, the model) says so. Output: the target (a copy with the new shift; ``target``
    itself when the shift stands) and the comparison at it (``cmp`` when the shift stands).
    """
    pool.expect(1)
    run = pool.map([raw])[0]
    if run.error:
        return target, cmp
    own = replace(target)
    own.align_to(run.t, run.signals)
    got, _ = checked_comparison(own, run)
    if got is None or own.shift == target.shift or not _lower(got, cmp, target.sigma):
        return target, cmp
    nz.notes.append(f"time shift aligned again on the model with {label}: {1e3 * target.shift:.4f} -> "
                    f"{1e3 * own.shift:.4f} ms (J {cmp.objective:.4g} -> {got.objective:.4g})")
    nz.shift = float(own.shift)
    return own, got


def _speed_between(pool: Pool, target: Target, nz: NuisanceFit, raw: dict, cmp: Comparison,
                   label: str) -> tuple[Target, NuisanceFit, dict, Comparison]:
    """Step 4b, then: the speed found again from the data on the model with the first named cause (``raw``,
    compared as ``cmp``), before round 2 (:func:`orchestrator.inverse.nuisance.speed_again`, as step 5c does
    after the rounds), kept when it fits better by step 5c's rule (:func:`_lower`).

    Stage 1 finds the speed on the nominal run, and a large track effect moves the warp that fits it best
    (module doc, 5c): round 2 would weigh its candidates against a reference that still carries that speed
    error. Measured on issue 14's field-like worn_nose+mismatch 7000 (a worn nose beside a vehicle
    mismatch, the truth's speed 34.566 m/s): stage 1 found 33.228, here 34.144 (J 0.2395 -> 0.1608).

    Output: the target, the nuisance estimates, the model and its comparison: ``target``, ``nz``, ``raw``,
    ``cmp`` when the speed stands (``nz`` then counts the runs made and says why); else the target at the
    new shift, a copy of ``nz`` at the new speed (its ``raw``: the nuisance model without causes at it, the
    reference the causes are fitted again on in step 5b), ``raw`` at the new speed and its comparison.
    """
    from orchestrator.inverse.nuisance import _at_speed, speed_again

    mine = copy.deepcopy(nz)
    got = speed_again(pool, target, mine, raw, cmp, f"with {label}")
    if got is None:
        return target, nz, raw, cmp
    if not _lower(got[2], cmp, target.sigma):
        nz.runs = mine.runs
        nz.notes.append(f"speed again with {label}: {nz.values['speed']:.3f} -> {mine.values['speed']:.3f} m/s "
                        f"fits no better (J {cmp.objective:.4g} -> {got[2].objective:.4g}, chi-square "
                        f"{cmp.chi2:.4g} -> {got[2].chi2:.4g}): not kept")
        return target, nz, raw, cmp
    mine, raw_v, cmp_v = got
    mine.raw = _at_speed(nz.raw, float(mine.values["speed"]), float(raw_v["simulation"]["duration"]))
    return replace(target, shift=cmp_v.shift), mine, raw_v, cmp_v


def _moved(pool: Pool, target: Target, nz: NuisanceFit, raw: dict, cmp: Comparison,
           label: str) -> tuple[Target, NuisanceFit, dict, Comparison]:
    """Step 4b: :func:`_aligned_again`, then :func:`_speed_between` on the model with ``label`` (``raw``,
    compared as ``cmp``). Output: what :func:`_speed_between` returns."""
    target, cmp = _aligned_again(pool, target, nz, raw, cmp, label)
    return _speed_between(pool, target, nz, raw, cmp, label)


def _further(inp: _Inputs, ref: Evaluated) -> list[Candidate]:
    """Step 3b: the local candidates up to :data:`FAR_REACH` sleepers beyond the sensors not yet screened,
    when the reference's residual is above the noise (else none: a residual at the noise level asks for
    no cause, and a named cause for no further look)."""
    if at_noise_level(ref.cmp, inp.target)[0]:
        return []
    have = set(inp.cands)
    return [c for c in candidates(sleepers_of(inp.sensors), len(inp.sleeper_x), FAR_REACH) if c not in have]


def _backfit(pool: Pool, target: Target, ref_raw: dict, ref: Evaluated, named: list[_Named]) -> None:
    """Step 5b: each named cause fitted again on the reference with the other at its latest values (module doc).

    One pass, in the order named: all of a cause's parameters (the finest stage of
    :func:`orchestrator.inverse.selection.cause_stages`) from its current values; each
    start is the current extended model itself (no run needed to know its comparison).
    A refit that fits better by step 5c's rule (:func:`_lower`) is kept: the cause's ``refit`` (and its fitter, for the
    intervals), and the last cause's ``raw``, the extended model, takes the new values.
    """
    values = [n.e.values for n in named]
    current = named[-1].e.cmp
    for i, n in enumerate(named):
        c = n.e.candidate
        kind = kind_of(c)
        raw = ref_raw
        for j, m in enumerate(named):
            if j != i:
                raw = kind_of(m.e.candidate).apply(raw, m.e.candidate.sleeper, values[j])
        start = Evaluated(c, values[i], current, n.e.k, "fitted")
        fitter = CauseFitter(pool, target, raw, start, ref.cmp)
        fitter.known(values[i], current)
        stages = cause_stages(kind)
        pool.expect(FINE_MAX_NFEV * (stages[-1][0] + 1))
        got = fitter.fit(start, slice(len(stages) - 1, None), FINE_MAX_NFEV)
        if _lower(got.cmp, current, target.sigma):   # never a worse fit (step 5c's rule)
            n.refit, n.refit_fitter, n.refit_from = got, fitter, current.objective
            values[i], current = got.values, got.cmp
            named[-1].raw = kind.apply(raw, c.sleeper, got.values)


def _final(named: list[_Named]) -> Comparison:
    """The comparison of the model with the named causes: the last refit (step 5b), else the last named cause's
    (at the shift and speed of step 4b, when it moved them)."""
    for n in reversed(named):
        if n.refit is not None:
            return n.refit.cmp
    return named[-1].moved or named[-1].e.cmp


def _second_round(target: Target, first: Round, named: list[_Named]) -> list[Candidate]:
    """Step 5: the :data:`SECOND_ROUND` candidates whose round-1 screening, superposed on the extended model,
    fits best (:func:`orchestrator.inverse.selection.superposed_ranking`; no runs), none on a named cause's site."""
    return superposed_ranking(target, first, named[-1].e, _free(first.screened, named))[:SECOND_ROUND]


def _free(cands, named: list[_Named]) -> list[Candidate]:
    """The candidates of ``cands`` on no named cause's site (one would overwrite the other)."""
    taken = [n.e.candidate for n in named]
    return [c for c in cands if not any(_same_site(c, t) for t in taken)]


def _at_the_residual(inp: _Inputs, target: Target, cmp: Comparison, speed: float, named: list[_Named],
                     chosen: list[Candidate]) -> list[Candidate]:
    """Step 5: round 1's local candidates at the sleeper nearest the peak of the residual left by the named
    cause(s) (``cmp``; :func:`orchestrator.inverse.significance.locate`) and at the sleeper of its loudest
    channel (:func:`_loudest_sleeper`), and its global causes, none of them yet ``chosen`` nor on a named
    cause's site; none when that residual is at the noise level (module doc)."""
    if at_noise_level(cmp, target)[0]:
        return []
    where = locate(cmp, target, inp.sensors, inp.sleeper_x, inp.x_start, speed)
    sites = {where["sleeper_nearest_peak"], *_loudest_sleeper(where["channels"], inp.sensors)}
    return [c for c in _free(inp.cands, named) if (c.sleeper is None or c.sleeper in sites) and c not in chosen]


def _loudest_sleeper(channels: list[dict], sensors) -> list[int]:
    """The sleeper carrying the first channel of ``channels`` (``locate``'s: the channels above their noise
    level, loudest first) that is on a sleeper; none when none is."""
    on = {s.id: sleeper_of(s.body) for s in sensors}
    return next(([on[ch["id"]]] for ch in channels if on.get(ch["id"]) is not None), [])


def _entry(e: Evaluated, rd: Round, rnd: int, ev: Evidence | None) -> CauseFit:
    """The typed result of one evaluated candidate of round ``rnd``, with its evidence."""
    ref = rd.reference.cmp
    best_bic = rd.bic[rd.real[0].candidate] if rd.real else None
    bic = rd.bic.get(e.candidate)
    evidence = {"round": rnd, "stage": e.stage, "objective_reference": ref.objective,
                "objective_reduction": ref.objective - e.cmp.objective, "chi2": e.cmp.chi2,
                "n_samples": e.cmp.n, "n_parameters": e.k, "bic_eff": bic,
                "delta_bic_eff_vs_best": None if bic is None else bic - best_bic,
                "indistinguishable_from": rd.twins.get(e.candidate, [])}
    if ev is not None:
        evidence["significance"] = ev.to_json()
    return CauseFit(e.candidate.cause, kind_of(e.candidate).parameters(e.values), e.cmp.objective,
                    1.0 - e.cmp.objective / ref.objective if ref.objective > 0 else 0.0, evidence,
                    sleeper=None if e.candidate.sleeper is None else int(e.candidate.sleeper))


def _named_entry(n: _Named, rnd: int, reach: tuple[int, int]) -> CauseFit:
    """A named cause: its entry, its ambiguity set and its 90 % intervals (:mod:`orchestrator.inverse.uncertainty`).

    ``reach``: the first and last sleeper local candidates were placed on. A local cause
    named on one of them could as well sit further out, where nothing was screened: its
    ambiguity set says so (``open_beyond``).
    """
    from orchestrator.inverse.uncertainty import cause_uncertainty

    entry = _entry(n.e, n.round, rnd, n.evidence)
    preferred = [c.label for c in n.preferred]
    close = n.round.twins.get(n.e.candidate, [])
    twins = close + [lab for lab in preferred if lab not in close]
    sleepers = sorted(({entry.sleeper} | {o.candidate.sleeper for o in n.round.real
                                          if o.candidate.label in twins and o.candidate.cause == n.e.candidate.cause})
                      - {None})
    entry.ambiguity = {"candidates": [n.e.candidate.label] + twins, "sleepers": sleepers}
    if preferred:
        entry.ambiguity["ranked_above"] = (f"{', '.join(preferred)} rank(s) above it on the effective sample size "
                                           "but remove less than the minimum share of the explainable misfit")
    if entry.sleeper is not None and entry.sleeper in reach:
        step = 1 if entry.sleeper == reach[1] else -1
        entry.ambiguity["open_beyond"] = (f"sleeper {entry.sleeper} is the outermost screened: the cause may as well "
                                          f"sit on sleeper {entry.sleeper + step} or further, not screened")
    fitter, values = n.round.fitters.get(n.e.candidate), n.e.values
    if n.refit is not None:   # step 5b: the parameters (and their intervals) of the refit with the other cause
        fitter, values = n.refit_fitter, n.refit.values
        kind = kind_of(n.e.candidate)
        entry.parameters = kind.parameters(values)
        entry.evidence["refit"] = {"parameters_round": kind.parameters(n.e.values),
                                   "objective_before": n.refit_from, "objective_after": n.refit.cmp.objective,
                                   "reason": "refitted on the model with the other named cause"}
    if fitter is not None:
        entry.uncertainty = cause_uncertainty(fitter, values, n.evidence.n_eff)
    return entry


def _answer(inp: _Inputs, ref: Evaluated, ref_raw: dict, named: list[CauseFit], final: Comparison,
            best: Evidence | None, step_err: dict | None = None, first: Round | None = None) -> Answer:
    """Step 6: named, ``none`` or ``unexplained`` (module doc), with where the residual lives when above noise.

    ``ref``/``ref_raw``: the model the causes were added to (nominal, or with the nuisance
    estimates); ``final``: the comparison of the model with all named causes; ``best``: the
    evidence of round 1's best candidate (why nothing was named); ``step_err``: the model's
    own time-step error (:func:`_step_error`), reported where the residual lives; ``first``: round 1, whose
    screening runs say what a ``none`` answer's record resolves (:func:`orchestrator.inverse.resolution.resolution`).
    """
    quiet, j_noise, _ = at_noise_level(final, inp.target)
    where = None if quiet else locate(final, inp.target, inp.sensors, inp.sleeper_x,
                                      inp.x_start, float(ref_raw["vehicle"]["speed"]))
    if where is not None and step_err is not None:
        where["model_step_error"] = step_err
    if named:
        text = "; ".join(f"{c.cause}{'' if c.sleeper is None else f' at sleeper {c.sleeper}'} removes "
                         f"{100 * c.gain:.1f} % of the objective" for c in named)
        rest = "the rest is at the noise level" if quiet else "a residual above the noise remains (see where)"
        return Answer("named", named, f"{text}; {rest}.", where)
    why = "; ".join(best.reasons) if best is not None else "no candidate could be evaluated"
    ref_quiet, _, loud = at_noise_level(ref.cmp, inp.target)
    if ref_quiet:
        limits = resolution(inp.target, first.reference.cmp, first.proxies) if first is not None else None
        words = summary(limits) if limits else ""
        return Answer("none", [], f"the residual is at the noise level (J {ref.cmp.objective:.4g} <= "
                                  f"{1 + NONE_MARGIN:g} x the noise's {j_noise:.4g}, no channel above "
                                  f"{LOUD_FACTOR:g} x its own noise level, no displacement above "
                                  f"{LOUD_FACTOR:g} x its group's median residual)" + (f"; {words}" if words else ""),
                      None, limits)
    return Answer("unexplained", [], f"the residual is above the noise (J {ref.cmp.objective:.4g}, noise "
                                     f"{j_noise:.4g}{_loud_words(loud, inp.target.layout.types)}) and no "
                                     f"catalogue cause explains it: the "
                                     f"best candidate {why}" + _step_words(step_err, j_noise), where)


def _loud_words(loud: dict, types: dict) -> str:
    """The unexplained answer's note on the channels whose residual stands above their own noise level (a
    reconstructed displacement: above its group's median residual, :func:`orchestrator.inverse.significance.standing_out`)."""
    if not loud:
        return ""
    top = list(loud.items())[:3]
    return "; channel(s) " + ", ".join(
        f"{k} at {v:.3g} x " + ("its group's median residual" if types.get(k) == "displacement" else
                                "its own noise level") for k, v in top)


def _step_words(step_err: dict | None, j_noise: float) -> str:
    """The unexplained answer's note when the model's own time-step error alone, extrapolated to the converged
    model, exceeds the noise objective.

    The half-step run's difference is a lower bound of the error (:func:`orchestrator.inverse.significance.step_error`);
    Richardson's extrapolation at order :data:`SIGNAL_STEP_ORDER` gives the error against the converged model,
    ``J_half x 2^p / (2^p - 1)`` (twice it at first order). Until 2026-11-29 the note compared the half-step
    difference itself and stayed silent on issue 14's pad_local+mismatch 7101, where it read 0.95 x the noise
    (RESULTS, session 32)."""
    if step_err is None:
        return ""
    converged = _converged(step_err["objective"])
    if not converged > j_noise:
        return ""
    g, v = max(step_err["groups"].items(), key=lambda kv: kv[1])
    return (f"; the model's own time-step error alone is J {step_err['objective']:.3g} against its run at half the "
            f"step ({0.5 * step_err['step']:g} s; most in group {g}, nRMSE {v:.3g}), about {converged:.3g} against "
            f"the converged model (order {SIGNAL_STEP_ORDER}), above the noise: a finer simulation.step may resolve what no cause "
            f"does at this one")


def _legacy_named(answer: Answer, base: Evaluated, best: Evidence | None, best_label: str | None) -> CauseFit:
    """``named_cause`` of the first schema: the first named cause, or ``none`` / ``unexplained`` with the reason."""
    if answer.causes:
        return answer.causes[0]
    return CauseFit(answer.kind, {}, base.cmp.objective, 0.0,
                    {"best_candidate": best_label, "delta_bic_vs_nominal": None if best is None else best.delta_bic,
                     "threshold": DELTA_BIC, "reason": answer.reason})


def _extend(inp: _Inputs, ext_raw: dict) -> Path:
    """Step 7: write the extended model (the reference with all named causes) as ``extended.yaml``."""
    from orchestrator.inputs.scenario import dump_scenario, scenario_from_dict

    ext_scenario = scenario_from_dict(copy.deepcopy(ext_raw), source=str(inp.scenario_path),
                                      base_dir=Path(inp.scenario_path).parent)
    return dump_scenario(ext_scenario, inp.out_dir / "extended.yaml")


def _validate(pool: Pool, inp: _Inputs, ext_raw: dict) -> list[Passage]:
    """Step 7, further passages: nominal and extended model at each passage's speed, compared without refitting.

    Input: the pool, the inputs, the extended raw scenario. Output: one :class:`Passage`
    per ``--validate`` file that could be compared (the others are dropped with their reason).
    """
    validation = []
    for vt, vpath, speed in inp.validations:
        pool.expect(2)
        r_before, r_after = pool.map([variant_for_speed(inp.raw0, speed), variant_for_speed(ext_raw, speed)])
        if r_before.error:
            pool.drop(f"validation {vpath}@{speed:g}", "validation", f"the nominal run stopped early: {r_before.error}")
            continue
        vt.align_to(r_before.t, r_before.signals)
        (cb, why_b), (ca, why_a) = checked_comparison(vt, r_before), checked_comparison(vt, r_after)
        if cb is None or ca is None:
            pool.drop(f"validation {vpath}@{speed:g}", "validation", why_b or why_a)
            continue
        validation.append(Passage(str(vpath), speed, cb.objective, ca.objective,
                                  1.0 - ca.objective / cb.objective if cb.objective > 0 else 0.0,
                                  {k: {"nrmse_before": cb.channels[k]["nrmse"], "nrmse_after": ca.channels[k]["nrmse"]}
                                   for k in cb.channels}))
    return validation


def _total_gain(before: Comparison, after: Comparison) -> Gain:
    """Step 7, gain: of the extended model (``after``) over the nominal one (``before``), total and per channel."""
    return Gain(1.0 - after.objective / before.objective if before.objective > 0 else 0.0,
                {k: 1.0 - after.channels[k]["nrmse"] / v["nrmse"] if v["nrmse"] > 0 else 0.0
                 for k, v in before.channels.items()})


def _settings(cands: list[Candidate], looked_further: bool = False) -> dict:
    """The thresholds of the diagnosis, whether round 1 looked further (step 3b) and the candidates' labels
    (``diagnosis.json`` ``settings``)."""
    return {"delta_bic": DELTA_BIC, "min_share": MIN_SHARE, "cv_tol": CV_TOL, "none_margin": NONE_MARGIN,
            "loud_factor": LOUD_FACTOR, "confirm": CONFIRM, "fit": FIT, "sensor_reach": SENSOR_REACH,
            "far_reach": FAR_REACH, "looked_further": looked_further, "max_causes": MAX_CAUSES,
            "second_round": SECOND_ROUND, "second_confirm": SECOND_CONFIRM,
            "candidates": [c.label for c in cands]}


def _write_outputs(result: Diagnosis, inp: _Inputs, before: Comparison, after: Comparison, executor=None) -> None:
    """Write ``diagnosis.json`` and the report (``report.md`` and its plots) into the output folder.

    Input: the diagnosis, the inputs, the nominal and the extended model's comparisons, and the
    executor whose (by then idle) workers draw the plots.
    """
    from orchestrator.inverse.diagnose_report import write_report

    (inp.out_dir / "diagnosis.json").write_text(json.dumps(result.to_json(), indent=1, default=numpy_default))
    write_report(inp.out_dir, result, inp.target, before, after, inp.layout, executor)


def _result(inp: _Inputs, base: Evaluated, ref: Evaluated, ref_raw: dict, named_entries: list[CauseFit],
            rounds: list, evidence: dict, final: Comparison,
            step_err: dict | None = None) -> tuple[Answer, list[CauseFit], CauseFit]:
    """Steps 4-6 as typed results: the answer, every candidate's entry, ``named_cause``.

    ``named_entries``: the named causes' entries (:func:`_named_and_nuisance_again`);
    ``final``: the comparison of the extended model (with the nuisance values of step 5c).
    """
    first = rounds[0]
    best_ev = evidence.get((1, first.real[0].candidate)) if first.real else None
    answer = _answer(inp, ref, ref_raw, named_entries, final, best_ev, step_err, first)
    causes = [_entry(e, rd, i + 1, evidence.get((i + 1, e.candidate))) for i, rd in enumerate(rounds)
              for e in rd.ranked]
    legacy = _legacy_named(answer, base, best_ev, first.real[0].candidate.label if first.real else None)
    return answer, causes, legacy


def diagnose(scenario_path, measured_path, out_dir, validate=(), workers: int | None = None, scheduler: str | None = None,
             progress: bool = True) -> Diagnosis:
    """Run the diagnosis (module docstring); write diagnosis.json, extended.yaml, report.md, plots.

    ``baseline.json`` (the nominal model's residuals: step 1) is written as soon as it is
    known, so a diagnosis that fails later keeps it.

    Parameters
    ----------
    scenario_path : path-like
        The nominal scenario.
    measured_path : path-like
        The measured passage (CSV, HDF5, MAT; :mod:`orchestrator.inputs.measured`).
    out_dir : path-like
    validate : sequence of str
        Further passages as ``FILE@SPEED`` (speed in m/s): compared before/after, not fitted.
    workers : int, optional
        Local worker processes (default: one per core).
    scheduler : str, optional
        Dask scheduler address.
    progress : bool

    Returns
    -------
    Diagnosis
        The answer; its :meth:`~orchestrator.inverse.diagnosis.Diagnosis.to_json` is diagnosis.json.
    """
    from tqdm import tqdm

    from orchestrator.sweeps.executors import executor_slots, make_executor

    t_start = time.perf_counter()
    inp = _read_inputs(scenario_path, measured_path, out_dir, validate)
    executor = make_executor(workers, scheduler)
    bar = tqdm(total=1, desc="diagnose", unit="run", disable=not progress)
    # the workers beyond the first run a small fit's Jacobian ahead of its trial point (Pool.spare); runs wait in
    # the pool for a free worker, the shortest queue's first (Pool.slots)
    slots = executor_slots(executor)
    pool = Pool(executor, str(scenario_path), bar=bar, spare=slots - 1, slots=slots)
    try:
        base, baseline = _baseline(pool, inp)
        ref_raw, ref, nuisance = _nuisance(pool, inp, base)
        step_err = _step_error(pool, inp, ref_raw, ref)   # runs beside round 1's screening, waited for after it
        named, rounds, evidence, nuisance, ref_raw, ref = _rounds(pool, inp, ref_raw, ref, nuisance, step_err)
        ext_raw, final = (named[-1].raw, _final(named)) if named else (ref_raw, ref.cmp)
        entries, nuisance, ext_raw, final = _named_and_nuisance_again(pool, inp, named, nuisance, ext_raw, final)
        ext_raw, final = _causes_again(pool, inp, named, entries, nuisance, ext_raw, final)
        ext_path = _extend(inp, ext_raw)
        validation = _validate(pool, inp, ext_raw)
        step_json = step_err()
        if step_json is not None:   # the speed's interval gets the model's own time-step error
            widen_speed_for_step(nuisance, step_json["speed_ratio"], step_json["speed_bias"], step_json["step"])
        answer, causes, legacy = _result(inp, base, ref, ref_raw, entries, rounds, evidence, final, step_json)
        result = Diagnosis(str(scenario_path), str(measured_path), answer, baseline, nuisance.to_json(), causes,
                           legacy,
                           ext_path.name, _total_gain(base.cmp, final), validation, pool.dropped, pool.runs,
                           time.perf_counter() - t_start, _settings(inp.cands, inp.looked_further),
                           {"runs": pool.ahead_runs, "used": pool.ahead_used})
        _write_outputs(result, inp, base.cmp, final, executor)   # the workers draw the report's plots
    finally:
        bar.close()
        pool.close()
        executor.shutdown(wait=True, cancel_futures=True)
    return result


def _hypothesis_again(pool: Pool, inp: _Inputs, nz: NuisanceFit, raw: dict, cmp: Comparison) -> Comparison:
    """A hypothesis's model after steps 4b (:func:`_moved`) and 5c (:func:`_nuisance_again`), as a diagnosis
    that named its causes leaves it (``nz`` is changed)."""
    _, nz, raw, cmp = _moved(pool, inp.target, nz, raw, cmp, "the hypothesis")
    return _nuisance_again(pool, inp, nz, raw, cmp)[2]


def hypothesis_gains(scenario_path, measured_path, hypotheses, out_dir, workers: int | None = None,
                     scheduler: str | None = None) -> dict:
    """How much of the misfit given cause sets explain, measured as :func:`diagnose` measures a named cause's.

    Steps 1-2 of the diagnosis (the nominal run, the nuisance fit: the same reference, the same
    numbers), then one run per hypothesis: its causes applied to the reference at the given
    values, no fitting of theirs, then step 4b (the shift and the speed found again on that model,
    :func:`_moved`) and step 5c (the nuisance values fitted again on that model and its speed found
    again, the best point kept by :func:`_lower`; not step 5d: the
    hypothesis's values are given, not fitted). A hypothesis's gain is ``1 - J / J_nominal``, the definition of
    ``diagnosis.json``'s ``gain.total``. For a cause a user knows of (an inspection found a
    void) — and for the benchmark of issue 14, which asks what the *true* effects would gain on
    a record (``benchmarks/bench_diagnose_field.py --truth-gain``): a named cause's gain is
    bounded by that, however good the diagnosis.

    Parameters
    ----------
    scenario_path, measured_path, out_dir, workers, scheduler
        As for :func:`diagnose` (``baseline.json`` is written to ``out_dir``).
    hypotheses : list of list of dict
        Each a list of causes ``{"cause", "sleeper" (or None), "parameters"}`` (the entries of
        ``diagnosis.json``'s ``answer.causes`` have that form).

    Returns
    -------
    dict
        ``objective_nominal``, ``objective_reference`` (with the nuisance estimates), and
        ``hypotheses``: per hypothesis ``{"objective", "gain"}``, or ``{"error"}`` naming why its
        run cannot be compared.
    """
    from orchestrator.inverse.synthetic import Effect
    from orchestrator.sweeps.executors import make_executor

    for causes in hypotheses:
        for c in causes:
            if c.get("cause") not in CATALOGUE:
                raise UserInputError(f"hypothesis cause {c.get('cause')!r} is not one of {', '.join(CATALOGUE)}")
    inp = _read_inputs(scenario_path, measured_path, out_dir, ())
    executor = make_executor(workers, scheduler)
    try:
        pool = Pool(executor, str(scenario_path))
        base, _ = _baseline(pool, inp)
        ref_raw, ref, nz = _nuisance(pool, inp, base)
        raws = []
        for causes in hypotheses:
            raw = ref_raw
            for c in causes:
                raw = Effect(c["cause"], c.get("sleeper"), c["parameters"]).apply(raw)
            raws.append(raw)
        got = pool.map(raws, then=lambda run: checked_comparison(inp.target, run, ref.cmp))
        # steps 4b and 5c as for named causes: the shift and the speed found again on the hypothesis's model,
        # then the nuisance values fitted again with its causes
        got = [(_hypothesis_again(pool, inp, copy.deepcopy(nz), raw, cmp), None) if cmp is not None and hyp
               else (cmp, why) for raw, hyp, (cmp, why) in zip(raws, hypotheses, got)]
    finally:
        executor.shutdown(wait=True, cancel_futures=True)
    j0 = base.cmp.objective
    return {"objective_nominal": j0, "objective_reference": ref.cmp.objective,
            "hypotheses": [{"objective": cmp.objective, "gain": 1.0 - cmp.objective / j0 if j0 > 0 else 0.0}
                           if cmp is not None else {"error": why} for cmp, why in got]}


__all__ = ["diagnose", "hypothesis_gains", "DELTA_BIC", "Diagnosis", "CauseFit", "SENSOR_REACH", "FAR_REACH",
           "MAX_CAUSES", "SECOND_ROUND", "SECOND_CONFIRM"]
