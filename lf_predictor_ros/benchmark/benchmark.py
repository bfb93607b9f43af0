"""`benchmark`: the fair scenario suite, closed loop first, on Dask, and the results page.

    benchmark                               # full suite → docs/RESULTS.md, runs/benchmark-*.json
    benchmark --scheduler tcp://HOST:8786   # the same cases on an existing Dask cluster
    benchmark --fast -o /tmp/r.md           # smoke run (CI, < 2 min): two short cases

Seeds: the tuning seeds (1 and 2: the predictor's defaults and the baselines' settings in
config/baselines were chosen on them) are never run here; the tables report ``--seeds`` held-out
seeds starting at ``--first-seed`` (11 by default), as means with a 95 % interval (Student t).
Every case is one Dask task (`benchmark.distributed`): an in-process LocalCluster with one
single-threaded worker per core unless ``--scheduler`` names a cluster; a case gives the same
numbers wherever it runs.

Per scenario the page has, in this order: the **closed-loop** table (every causal estimator in its
own DP loop; `suite.run_closed_loops`) with the targets of the method issue; the **open-loop**
table on the fair recording (the DP loop closed on ``--recording-loop``, the tuned observer by
default), with the recording's provenance and the thrust-only leak check; the adaptation table
for ω0 schedules. Targets are printed met / MISSED, never hidden. The station-keeping scenarios
of `LONG_RUNS` run a second time for two hours on the same seeds, in sections of their own
(``supply_closed_loop, 7200 s runs``); ``--no-long-runs`` skips them.
"""
from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
import datetime as dt
from functools import partial
import json
import math
from pathlib import Path
import sys
import time
from typing import Any

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.adaptation import FROZEN_RATIO, RECOVERY_WINDOWS, TOLERANCE
from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS
from lf_predictor_ros.benchmark.distributed import IN_PROCESS, CaseSpec, run_cases
from lf_predictor_ros.benchmark.estimators import param_overrides
from lf_predictor_ros.benchmark.scoring import fmt_number, interval, ratios, verdict
from lf_predictor_ros.benchmark.suite import (
    CAUSAL,
    DEFAULT_RECORDING_LOOP,
    ESTIMATORS,
    LIMITS,
    LOOP_ESTIMATORS,
    CaseResult,
    schedule_shift_for_seed,
)
from lf_predictor_ros.core.evaluation import DOF_NAMES
from lf_predictor_ros.core.params import PredictorParams
from sim_ros.physics.schedule import delayed
from sim_ros.simulation import available_scenarios, load_scenario

# scenario → simulated duration [s] (None = the scenario's own). 1800 s: the first training and
# 2Δ of warm-up leave 1319 scored samples; rao_swell's schedule holds a 90° turn at 1600 s.
# onedof_excited, onedof_no_excitation, omega_schedule: `--scenarios NAME` (not in the default).
SUITE: dict[str, float | None] = {
    'supply_closed_loop': 1800.0,
    'rao_supply': 1800.0,
    'rao_swell': 1800.0,
    # the unseen hulls, large and small: never used in development (seventy-third session)
    'rao_tanker': 1800.0,
    'rao_workboat': 1800.0,
    'onedof_feedback': 1800.0,
    'onedof_reference': 1800.0,
    'threedof_open_loop': 1800.0,
    'omega_steps': None,  # the adaptation benchmark (ω0 steps 1.25 → 0.3 → 1.25 rad/s, 3 h)
}
# scenario → a second, long run of the same seeds [s]: a DP operation lasts hours, and 1800 s
# runs miss what takes time to show (late limit cycles once the training window has slid past
# the start's excitation) and weigh the warm-up (docs/BENCHMARKS.md, thirty-sixth session: two
# hours moved the station-keeping verdicts both ways). Station keeping only: these scenarios
# have no setpoint schedule, so run length is the only difference. `--no-long-runs` drops them.
LONG_RUNS: dict[str, float] = {'supply_closed_loop': 7200.0, 'onedof_feedback': 7200.0}
# 900 s for the 3-DOF case: its linear limit fits 106 coefficients on ≥ 424 scored samples
FAST_SUITE: dict[str, float | None] = {'onedof_feedback': 600.0, 'supply_closed_loop': 900.0}
FAST_OVERRIDES = {'max_epochs': 15}  # smoke run only: fewer epochs per training
FIRST_HELD_OUT_SEED = 11
HELD_OUT_SEEDS = 10
# method issue targets (held-out seeds, every DOF, shipped defaults)
THRUST_OF_RAW = 0.03  # loop thrust wave-band power ≤ 3 % of the raw loop's
POSITION_OF_ORACLE = 1.1  # loop position RMSE ≤ 1.1 × the oracle-KF loop's
OPEN_OF_ORACLE = {1: 2.0, 3: 1.1}  # open-loop RMSE ≤ this × the oracle KF's, by ndof
OPEN_OF_OBSERVER = 0.8  # open-loop RMSE ≤ 0.8 × the tuned observer's
OPEN_OF_LINEAR_LIMIT = 1.1  # RAO vessels: ≤ 1.1 × the linear limit's
OUTPUT_STEP_RATIO = 3.0  # largest output step ≤ this × the largest true LF step, every run
FIGURE_DIR = 'results'  # next to the results page
RAO_ORACLE_NOTE = (' Here oracle_kf knows the vessel, environment and noise but models the RAO '
                   'sea by a 2nd-order filter fitted to its peak and variance: a strong '
                   'baseline, not a limit.')
# [s] default --schedule-spread: one retraining period, so the held-out seeds draw the phase
# between trainings and scheduled events (docs/BENCHMARKS.md, twenty-second session)
SCHEDULE_SPREAD = PredictorParams().retrain_period
EPS_TIME = 1e-6  # [s] 'just before' a change time (schedules are right-continuous at steps)


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='benchmark', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--fast', action='store_true', help='short smoke run (CI)')
    parser.add_argument('--seeds', type=int, default=HELD_OUT_SEEDS,
                        help=f'held-out seeds per scenario (default {HELD_OUT_SEEDS})')
    parser.add_argument('--first-seed', type=int, default=FIRST_HELD_OUT_SEED,
                        help=f'first held-out seed (default {FIRST_HELD_OUT_SEED}; seeds '
                        f'{TUNING_SEEDS} are tuning seeds and refused)')
    parser.add_argument('--scenarios', nargs='*', help='subset of the suite')
    parser.add_argument('--duration', type=float,
                        help='override every duration [s] (one run per scenario and seed)')
    parser.add_argument('--no-long-runs', action='store_true',
                        help='skip the second, long run of ' + ', '.join(
                            f'{name} ({seconds:.0f} s)' for name, seconds in LONG_RUNS.items()))
    parser.add_argument('--recording-loop', default=DEFAULT_RECORDING_LOOP, choices=CAUSAL,
                        help='estimator the open-loop recordings close their DP loop on')
    parser.add_argument('--scheduler', help="Dask scheduler address (tcp://HOST:PORT); default: "
                        f"a LocalCluster here; '{IN_PROCESS}': no Dask, one case at a time")
    parser.add_argument('--workers', type=int, help='LocalCluster workers (default: cores)')
    parser.add_argument('-o', '--output', default='docs/RESULTS.md', help='results page')
    parser.add_argument('--json', help='raw results (default runs/benchmark-<time>.json)')
    parser.add_argument('--schedule-spread', type=float, default=SCHEDULE_SPREAD,
                        metavar='SECONDS',
                        help='delay every scheduled event of a case (setpoint moves and turns, '
                        'wave peak frequency steps) by U(0, SECONDS) drawn from its seed, so '
                        "that the held-out seeds sample the phase between the predictor's "
                        'trainings and the events (default '
                        f'{SCHEDULE_SPREAD:g} s, the retraining period, as on docs/RESULTS.md; '
                        '0: the scenarios as written)')
    parser.add_argument('--param', action='append', default=[], metavar='FIELD=VALUE',
                        help='run the predictor with this PredictorParams value instead of '
                        'the shipped default (YAML value; repeatable), e.g. motion_gate=true')
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error('need --seeds >= 1 held-out seed')
    if not (math.isfinite(args.schedule_spread) and args.schedule_spread >= 0.0):
        parser.error(f'--schedule-spread must be finite and >= 0 s, got {args.schedule_spread}')
    try:
        args.param = param_overrides(args.param)
    except ValueError as exc:
        parser.error(str(exc))
    held_out = range(args.first_seed, args.first_seed + args.seeds)
    if not args.fast and any(s in TUNING_SEEDS for s in held_out):
        parser.error(f'held-out seeds {list(held_out)} overlap the tuning seeds {TUNING_SEEDS}: '
                     'choose --first-seed above them')
    return args


# ------------------------------------------------------------------------------ cells
def _fmt_dof(value: float, dof: str) -> str:
    if not math.isfinite(value):
        return str(value)
    return f'{value:.4f}' if dof != 'yaw' else f'{value:.5f}'


def _open_values(cases: list[CaseResult], name: str, i: int) -> list[float]:
    return [c.metrics[name].rmse[i] if name in c.metrics else math.nan for c in cases]


def _step_values(cases: list[CaseResult], name: str, i: int) -> list[float]:
    """`Metrics.largest_step_ratio` of DOF i per case (cases without it left out)."""
    return [c.metrics[name].largest_step_ratio[i] for c in cases
            if name in c.metrics and c.metrics[name].largest_step_ratio]


def _loop_values(cases: list[CaseResult], loop: str, key: str,
                 dof: str | None = None) -> list[float]:
    out = []
    for c in cases:
        entry = c.closed_loop.get(loop)
        if entry is None or key not in entry:
            out.append(math.nan)
        else:
            out.append(float(entry[key] if dof is None else entry[key][dof]))
    return out


def _has_loop(cases: list[CaseResult], loop: str) -> bool:
    return any(loop in c.closed_loop for c in cases)


def _stable_cell(cases: list[CaseResult], loop: str) -> str:
    runs = [c for c in cases if loop in c.closed_loop]
    failures = [f'seed {c.seed}: {c.closed_loop[loop]["stability"]["reason"]}' for c in runs
                if not c.closed_loop[loop]['stability']['stable']]
    head = f'{len(runs) - len(failures)}/{len(runs)}'
    return head if not failures else head + ' (' + '; '.join(failures[:3]) + \
        ('; …' if len(failures) > 3 else '') + ')'


def _pct(value: float) -> str:
    return f'{100.0 * value:.2g} %' if math.isfinite(value) else str(value)


# ------------------------------------------------------------------------------ tables
def _shift_note(cases: list[CaseResult]) -> str:
    """' Scheduled events … delayed by …' when cases ran with a schedule shift (else '')."""
    shifts = [float(c.info.get('schedule_shift', 0.0)) for c in cases]
    if not any(shifts):
        return ''
    return (' Scheduled events (setpoint moves and turns, ω0 steps) delayed per seed '
            '(`--schedule-spread`) by ' +
            ', '.join(f'{s:.1f}' for s in shifts) + ' s.')


def _reference_text(scenario: str) -> str:
    if load_scenario(scenario).controller.setpoint_schedule:
        return ("the ideal loop's LF track (setpoint moves and turns; the ideal loop's own "
                'error is 0 by definition)')
    return 'setpoint'


def _closed_loop_table(cases: list[CaseResult]) -> list[str]:
    ndof = cases[0].ndof
    dofs = DOF_NAMES[:ndof]
    loops = [name for name in LOOP_ESTIMATORS if _has_loop(cases, name)]
    raw_power = {d: _loop_values(cases, 'raw', 'thrust_wave_band_power', d) for d in dofs}
    lines = ['#### closed loop (primary)', '',
             f'The PID fed by each causal estimator, one estimate per h; true LF pose vs '
             f'{_reference_text(cases[0].scenario)} and applied thrust after the warm-up '
             f'({cases[0].warmup:.0f} s). Mean [95 % '
             'interval] over the seeds; max excursion: the worst seed. Thrust wave-band power '
             "per DOF as a share of the raw-measurement loop's (same seed); estimate wave "
             'band: the wave-band power of the estimate fed to the PID [m², m², rad²].', '',
             '| loop | position RMSE [m] | heading RMSE [rad] | max excursion [m] | '
             'thrust wave-band power / raw loop (' + ', '.join(dofs) + ') | thrust total '
             'variation (' + ', '.join(dofs) + ') | estimate wave band | stable |',
             '|---|---|---|---|---|---|---|---|']
    for loop in loops:
        heading = interval(_loop_values(cases, loop, 'heading_rmse')).cell(fmt_number) \
            if ndof == 3 else '–'
        shares = '; '.join(interval(ratios(_loop_values(cases, loop, 'thrust_wave_band_power',
                                                        d), raw_power[d])).cell(_pct)
                           for d in dofs)
        variation = ', '.join(fmt_number(interval(_loop_values(
            cases, loop, 'thrust_total_variation', d)).mean) for d in dofs)
        wave = ', '.join(fmt_number(interval(_loop_values(
            cases, loop, 'estimate_wave_band_power', d)).mean) for d in dofs) \
            if loop != 'ideal' else '–'
        excursion = max(_loop_values(cases, loop, 'max_excursion'), default=math.nan)
        lines.append(f'| {loop} | '
                     f'{interval(_loop_values(cases, loop, "position_rmse")).cell(fmt_number)} | '
                     f'{heading} | {fmt_number(excursion)} | {shares} | {variation} | {wave} | '
                     f'{_stable_cell(cases, loop)} |')
    return lines + [''] + _closed_loop_targets(cases, dofs)


def _closed_loop_targets(cases: list[CaseResult], dofs: Sequence[str]) -> list[str]:
    if not _has_loop(cases, 'adaptive'):
        return []
    lines = ['| target (method issue, closed loop) | value (mean [95 % interval] of per-seed '
             'ratios) | verdict |', '|---|---|---|']
    runs = [c.closed_loop['adaptive']['stability']['stable'] for c in cases
            if 'adaptive' in c.closed_loop]
    lines.append(f'| adaptive loop stable in every seed | {sum(runs)}/{len(runs)} | '
                 f'{verdict(all(runs))} |')
    checks = [('raw', THRUST_OF_RAW, 'thrust wave-band power adaptive / raw loop'),
              ('observer', 1.0, 'thrust wave-band power adaptive / observer loop')]
    for ref, bound, text in checks:
        if not _has_loop(cases, ref):
            continue
        cells, ok = [], True
        for d in dofs:
            iv = interval(ratios(_loop_values(cases, 'adaptive', 'thrust_wave_band_power', d),
                                 _loop_values(cases, ref, 'thrust_wave_band_power', d)))
            cells.append(f'{d} {iv.cell(fmt_number)}')
            ok = ok and iv.mean <= bound
        lines.append(f'| {text} ≤ {bound:g} per DOF | {"; ".join(cells)} | {verdict(ok)} |')
    for ref, bound in (('observer', 1.0), ('oracle_kf', POSITION_OF_ORACLE)):
        if not _has_loop(cases, ref):
            continue
        iv = interval(ratios(_loop_values(cases, 'adaptive', 'position_rmse'),
                             _loop_values(cases, ref, 'position_rmse')))
        lines.append(f'| position RMSE adaptive / {ref} loop ≤ {bound:g} | {iv.cell(fmt_number)} '
                     f'| {verdict(iv.mean <= bound)} |')
    return lines + ['']


def _provenance_line(cases: list[CaseResult]) -> str:
    labels = set()
    for case in cases:
        loop, estimator = case.provenance.get('loop'), case.provenance.get('estimator')
        labels.add('open loop (excitation only)' if loop == 'open' else
                   f'DP loop closed on {estimator}' if loop == 'estimator' else str(loop))
    return 'Recording: ' + ', '.join(sorted(labels)) + ' (`benchmark/recordings.py`).'


def _leak_line(cases: list[CaseResult]) -> str:
    reports = [c.leak for c in cases if c.leak]
    if not reports:
        return ("Leak check: not needed (open loop: the thrust is the scenario's excitation, "
                'computed from nothing; the motion is its response).')
    unchecked = [c.seed for c in cases if c.leak and not c.leak.get('checked', True)]
    if unchecked:
        return (f'Leak check: seeds {unchecked} too short for the data test (provenance checked '
                'only).')
    ndof = len(reports[0]['ratios'])
    worst = [min(r['ratios'][i] for r in reports) for i in range(ndof)]
    return ('Leak check (thrust-only linear fit on the truth / best causal estimator, per DOF, '
            f'must stay ≥ {reports[0]["factor"]:g}): lowest over the seeds '
            + ', '.join(f'{d} {w:.2f}' for d, w in zip(DOF_NAMES[:ndof], worst, strict=True))
            + ' — passed.')


def _untuned_note(cases: list[CaseResult]) -> str:
    if any(c.info.get('baselines') == 'untuned defaults' for c in cases):
        return (' **The classical baselines here run UNTUNED defaults** (no '
                'config/baselines file for this scenario: run baseline_tuning).')
    return ''


def _open_loop_table(name: str, cases: list[CaseResult]) -> list[str]:
    ndof = cases[0].ndof
    dofs = DOF_NAMES[:ndof]
    rao = load_scenario(name).waves.model == 'rao'
    lines = ['#### open loop', '',
             f'{cases[0].duration:.0f} s simulated, scored after {cases[0].warmup:.0f} s. '
             + _provenance_line(cases) + ' ' + _leak_line(cases) + ' RMSE of the LF estimate '
             'vs the true LF pose [m, m, rad], mean [95 % interval]; *limit* rows know the true '
             'model (oracle_kf) or are fitted on the truth (linear_limit); smoothers are '
             'non-causal. adaptive and frozen are scored at t + h (what they publish is the LF '
             'pose predicted for the next sample), every other row at t.'
             + (RAO_ORACLE_NOTE if rao else '') + _untuned_note(cases), '',
             '| estimator | ' + ' | '.join(dofs) + ' |', '|---|' + '---|' * ndof]
    for est in ESTIMATORS:
        if not any(est in c.metrics for c in cases):
            continue
        limit = est in LIMITS and not (rao and est == 'oracle_kf')
        label = f'*{est}* (limit)' if limit else est
        cells = [interval(_open_values(cases, est, i)).cell(partial(_fmt_dof, dof=d))
                 for i, d in enumerate(dofs)]
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return lines + [''] + _open_loop_targets(name, cases, dofs)


def _seen_truth_table(name: str, cases: list[CaseResult]) -> list[str]:
    """Open-loop RMSE against the LF truth the measurement carries (`seen_truth`): no verdict."""
    if load_scenario(name).waves.model == 'rao' or not all(c.seen_metrics for c in cases):
        return []
    dofs = DOF_NAMES[:cases[0].ndof]
    slow = [interval([c.info['slow_wave_rms'][i] for c in cases]).cell(partial(_fmt_dof, dof=d))
            for i, d in enumerate(dofs)]
    lines = ['#### open loop against the LF truth the measurement carries (reported, no verdict)',
             '', 'The twin truth above leaves out the first-order wave motion below the wave '
             "band (the shaping filter's own tail, and what the grid aliases down), which no "
             'filter of the measurement can tell from LF motion (`benchmark/seen_truth.py`). '
             'RMS of that slow wave motion: ' + ' / '.join(slow) + '. RMSE against the twin '
             'plus it (linear_limit left out: fitted on the twin):', '',
             '| estimator | ' + ' | '.join(dofs) + ' |', '|---|' + '---|' * len(dofs)]
    for est in ESTIMATORS:
        if not all(est in c.seen_metrics for c in cases):
            continue
        cells = [interval([c.seen_metrics[est].rmse[i] for c in cases]).cell(
            partial(_fmt_dof, dof=d)) for i, d in enumerate(dofs)]
        lines.append(f'| {est} | ' + ' | '.join(cells) + ' |')
    if all('adaptive' in c.seen_metrics and 'oracle_kf' in c.seen_metrics for c in cases):
        ratio = [interval(ratios([c.seen_metrics['adaptive'].rmse[i] for c in cases],
                                 [c.seen_metrics['oracle_kf'].rmse[i] for c in cases]))
                 for i in range(len(dofs))]
        lines += ['', 'adaptive / oracle_kf against this truth: '
                  + ' / '.join(iv.cell(fmt_number) for iv in ratio) + '.']
    return lines + ['']


def _open_loop_targets(name: str, cases: list[CaseResult], dofs: Sequence[str]) -> list[str]:
    ndof = cases[0].ndof
    if not any('adaptive' in c.metrics for c in cases):
        return []
    checks = [('oracle_kf', OPEN_OF_ORACLE[ndof]), ('observer', OPEN_OF_OBSERVER)]
    if name.startswith('rao'):
        checks.append(('linear_limit', OPEN_OF_LINEAR_LIMIT))
    lines = ['| target (method issue, open loop) | ' + ' | '.join(dofs) + ' | verdict |',
             '|---|' + '---|' * (ndof + 1)]
    for ref, bound in checks:
        if not any(ref in c.metrics for c in cases):
            continue
        ivs = [interval(ratios(_open_values(cases, 'adaptive', i), _open_values(cases, ref, i)))
               for i in range(ndof)]
        ok = all(iv.mean <= bound for iv in ivs)
        lines.append(f'| adaptive / {ref} ≤ {bound:g} | '
                     + ' | '.join(iv.cell(fmt_number) for iv in ivs) + f' | {verdict(ok)} |')
    worst = [max(_step_values(cases, 'adaptive', i), default=math.nan) for i in range(ndof)]
    if not any(math.isnan(w) for w in worst):  # nan: no case scored the adaptive
        lines.append(f'| adaptive: largest output step ≤ {OUTPUT_STEP_RATIO:g} × the largest true '
                     'LF step (one sample; worst seed) | '
                     + ' | '.join(fmt_number(w) for w in worst)
                     + f' | {verdict(all(w <= OUTPUT_STEP_RATIO for w in worst))} |')
    return lines + ['']


def _adaptation_table(cases: list[CaseResult]) -> list[str]:
    window = float(cases[0].info['params']['retrain_period'])
    written = load_scenario(cases[0].scenario).waves.peak_freq
    limit = RECOVERY_WINDOWS * window
    lines = ['#### adaptation to ω0 changes', '',
             f'Rolling RMSE over Δ = {window:g} s of the open-loop LF error. Steady = median of '
             "the adaptive predictor's rolling RMSE over the second half of the following "
             'segment (its settled level in the new sea); recovery = time after the change '
             'until the rolling RMSE stays ≤ '
             f'{TOLERANCE}× steady for Δ (inf: not before the next change); ratio = frozen / '
             f'adaptive RMSE over the {RECOVERY_WINDOWS:g}Δ after the change. Changes are the '
             'steps and ramp corners of the schedule; ω0 just before the change → at the end of '
             'the following segment.',
             '', '| seed | change [s] | ω0 [rad/s] | steady RMSE | adaptive RMSE 2Δ | '
             'frozen RMSE 2Δ | recovery [s] | frozen / adaptive |',
             '|---|---|---|---|---|---|---|---|']
    recoveries: list[float] = []
    ratios: list[float] = []
    for case in cases:
        events = case.adaptation or []
        # the case's own schedule (its events delayed by --schedule-spread's draw)
        schedule = delayed(written, float(case.info.get('schedule_shift', 0.0)))
        for i, event in enumerate(events):
            following = events[i + 1].time if i + 1 < len(events) else case.duration
            before, after = schedule(event.time - EPS_TIME), schedule(following - EPS_TIME)
            lines.append(f'| {case.seed} | {event.time:.0f} | {before:.2f} → {after:.2f} | '
                         f'{fmt_number(event.steady_rmse)} | '
                         f'{fmt_number(event.adaptive_rmse_after)} | '
                         f'{fmt_number(event.frozen_rmse_after)} | '
                         f'{fmt_number(event.recovery_time)} | {fmt_number(event.frozen_ratio)} |')
            recoveries.append(event.recovery_time)
            ratios.append(event.frozen_ratio)
    back = sum(r <= limit for r in recoveries)
    lines += ['', '| target (adaptation) | value | verdict |', '|---|---|---|',
              f'| adaptive back within {TOLERANCE}× steady RMSE within 2Δ = {limit:g} s after '
              f'every change | {back}/{len(recoveries)} changes | '
              f'{verdict(bool(recoveries) and back == len(recoveries))} |',
              f'| frozen ≥ {FROZEN_RATIO:g}× adaptive RMSE over the 2Δ after every change | '
              f'min {fmt_number(min(ratios, default=math.nan))} | '
              f'{verdict(bool(ratios) and min(ratios) >= FROZEN_RATIO)} |', '']
    return lines


def _stability_rule() -> str:
    lc = stability.LIMIT_CYCLE_AMPLITUDE
    return (f'Stability = bounded (max excursion ≤ max({stability.EXCURSION_FACTOR:g} × the ideal '
            f"loop's, {stability.EXCURSION_FLOOR:g} m), heading error ≤ max("
            f'{stability.EXCURSION_FACTOR:g} × ideal, {math.degrees(stability.HEADING_FLOOR):g}°'
            f'), not diverged beyond {stability.ABORT_EXCURSION:g} m) and no limit cycle (one LF '
            f'sinusoid explaining ≥ {stability.LIMIT_CYCLE_SHARE:.0%} of the pose-error variance '
            f'with an amplitude ≥ {lc[0]:g} m / {math.degrees(lc[2]):g}°, unless the ideal loop '
            f'shows it too with ≥ {stability.FORCED_SHARE:.0%} of the amplitude: then it is the '
            "response to the scenario's own excitation); see "
            '`lf_predictor_ros/benchmark/stability.py`.')


def write_figures(results: list[CaseResult], page: Path) -> dict[str, list[str]]:
    """PNGs of the first held-out seed of each section (`section_name`) next to the page.

    Returns the image links per section.
    """
    from lf_predictor_ros.benchmark.plots import plot_adaptation, plot_closed_loops

    folder = page.parent / FIGURE_DIR
    links: dict[str, list[str]] = {}
    for case in results:
        section = section_name(case.scenario, case.duration)
        if section in links:
            continue
        links[section] = []
        stem = section.replace(', ', '_').replace(' s runs', 's')
        if case.loop_series:
            folder.mkdir(parents=True, exist_ok=True)
            name = f'{stem}_closed_loop.png'
            plot_closed_loops(f'{section}, seed {case.seed}: closed loops',
                              case.loop_series, case.ndof, folder / name)
            links[section].append(f'{FIGURE_DIR}/{name}')
        if case.adaptation_series is not None:
            folder.mkdir(parents=True, exist_ok=True)
            name = f'{stem}_adaptation.png'
            plot_adaptation(f'{section}, seed {case.seed}: rolling RMSE of the LF '
                            'estimate, adaptive vs frozen', case.adaptation_series,
                            folder / name, 'm')
            links[section].append(f'{FIGURE_DIR}/{name}')
    return links


def render(results: list[CaseResult], command: str, wall: float, where: str,
           figures: Mapping[str, Sequence[str]] | None = None,
           overrides: Mapping[str, Any] | None = None) -> str:
    """The results page (markdown); ``figures``: a section's image links (`section_name`).

    ``overrides``: the PredictorParams values given instead of the shipped defaults (said on
    the page: then 'adaptive' is not the product as shipped).
    """
    seeds = sorted({c.seed for c in results})
    product = ('(shipped defaults)' if not overrides else
               '(shipped defaults except ' + ', '.join(f'`{k}: {v}`' for k, v in
                                                        sorted(overrides.items())) + ')')
    lines = ['# Results: adaptive LF predictor vs tuned classical wave filters', '',
             f'Generated by `{command}` on {dt.date.today().isoformat()} in {wall:.0f} s wall '
             f'({where}). Regenerate with the same command; the raw numbers are in the JSON it '
             'names.', '',
             'Estimators (`lf_predictor_ros/benchmark/estimators.py`): adaptive = the product '
             f"{product}; frozen = trained once (the thesis's static network); cascade "
             '= causal notch + low-pass at the true ω0 tuned for RMSE, cascade_loop_safe = tuned '
             'in the loop; observer = passive observer with the true M, D, ω0 and tuned gains; '
             'observer_mistuned = the same gains with M ×1.3, D ×0.7, ω0 ×1.2; oracle_kf = '
             'Kalman filter with the true model and noise (the limit); raw = the measurement; '
             "smoother_targets / smoother_tuned = zero-phase (non-causal) at the predictor's "
             'target settings / tuned; linear_limit = best causal linear filter on the '
             "predictor's regressors fitted on the truth in-sample. Baseline settings: "
             '`config/baselines/<scenario>.yaml` (tuned on the tuning seeds '
             f'{list(TUNING_SEEDS)} by `python -m lf_predictor_ros.benchmark.baseline_tuning`).',
             '',
             'No score is computed on data whose thrust came from the truth: closed-loop '
             'scenarios are recorded with the DP loop on a causal estimator, and every '
             'recording passes a provenance check and a thrust-only leak check before it is '
             'scored. ' + _stability_rule(), '',
             f'Held-out seeds: {seeds}. Tuning seeds (never in the tables): {list(TUNING_SEEDS)}.',
             '', 'What the numbers say, and where the learned filter loses: `docs/BENCHMARKS.md`,'
             ' "Fair benchmark".', '']
    by_section: dict[str, list[CaseResult]] = {}
    for case in results:
        by_section.setdefault(section_name(case.scenario, case.duration), []).append(case)
    for name, cases in by_section.items():
        lines += [f'### {name}', '', f'{len(cases)} held-out seed(s): '
                  f'{", ".join(str(c.seed) for c in cases)}.' + _shift_note(cases), '']
        if any(c.closed_loop for c in cases):
            lines += _closed_loop_table(cases)
        lines += _open_loop_table(cases[0].scenario, cases)
        lines += _seen_truth_table(cases[0].scenario, cases)
        if any(c.adaptation for c in cases):
            lines += _adaptation_table(cases)
        for link in (figures or {}).get(name, ()):
            lines += [f'![{name}]({link})', '']
    return '\n'.join(lines) + '\n'


def _durations(name: str, args: argparse.Namespace,
               suite: Mapping[str, float | None]) -> list[float | None]:
    """The runs of one scenario [s]: ``--duration``, else the suite's, then its long run."""
    if args.duration:
        return [args.duration]
    durations = [suite.get(name, SUITE.get(name))]
    if not (args.fast or args.no_long_runs) and name in LONG_RUNS:
        durations.append(LONG_RUNS[name])
    return durations


def _specs(args: argparse.Namespace) -> list[CaseSpec]:
    suite = FAST_SUITE if args.fast else SUITE
    names = args.scenarios or list(suite)
    seeds = [args.first_seed] if args.fast else list(range(args.first_seed,
                                                           args.first_seed + args.seeds))
    overrides = {**(FAST_OVERRIDES if args.fast else {}), **args.param}
    return [CaseSpec(name, seed, duration, overrides, args.recording_loop,
                     schedule_shift=schedule_shift_for_seed(seed, args.schedule_spread))
            for name in names for duration in _durations(name, args, suite)
            for seed in seeds]


def section_name(scenario: str, duration: float) -> str:
    """A case's section on the page: its scenario, and its run length if that is its long run.

    ``supply_closed_loop, 7200 s runs`` (`LONG_RUNS`). ``duration``: the run's simulated length
    [s]; its last sample is one step short, so it is read to the 10 s.
    """
    length = float(round(duration, -1))
    return f'{scenario}, {length:.0f} s runs' if LONG_RUNS.get(scenario) == length else scenario


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `benchmark` executable."""
    args = _parse(argv)
    known = set(SUITE) | set(FAST_SUITE) | set(available_scenarios())
    unknown = [n for n in args.scenarios or [] if n not in known]
    if unknown:
        print(f'benchmark: unknown scenario(s) {unknown}; the suite is {list(SUITE)}',
              file=sys.stderr)
        return 2
    for name in args.scenarios or (FAST_SUITE if args.fast else SUITE):
        load_scenario(name)  # a broken scenario file fails here, before any case runs
    specs = _specs(args)
    start = time.monotonic()
    where = ('in this process' if args.scheduler == IN_PROCESS else
             f'Dask scheduler {args.scheduler}' if args.scheduler else
             f'Dask LocalCluster, {args.workers or "one worker per core"}, 2-core machine')
    results = run_cases(specs, args.scheduler, args.workers)
    wall = time.monotonic() - start
    command = 'benchmark ' + ' '.join(argv if argv is not None else sys.argv[1:])
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    figures = write_figures(results, Path(args.output))
    page = render(results, command.strip(), wall, where, figures, args.param)
    Path(args.output).write_text(page, encoding='utf-8')
    raw_path = Path(args.json or f'runs/benchmark-{dt.datetime.now():%Y%m%d-%H%M%S}.json')
    raw_path.parent.mkdir(parents=True, exist_ok=True)
    payload: dict[str, Any] = {'command': command, 'wall_seconds': wall,
                               'tuning_seeds': list(TUNING_SEEDS),
                               'cases': [c.to_dict() for c in results]}
    raw_path.write_text(json.dumps(payload, indent=1, default=float), encoding='utf-8')
    print(page)
    print(f'[benchmark] wrote {args.output} and {raw_path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
