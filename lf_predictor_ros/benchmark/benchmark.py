"""`benchmark`: the scenario suite with every estimator side by side, and the results page.

    benchmark                       # full suite → docs/RESULTS.md and runs/benchmark-*.json
    benchmark --fast -o /tmp/r.md   # smoke run (CI): two short scenarios, one seed

Seeds are split: the first `--tuning-seeds` seeds (seed 1 by default) are the ones the method was
tuned on during development and are not run here; the tables report the held-out seeds only.
Targets (issue 6) are checked on the held-out means and printed as met / MISSED, never hidden.

Per scenario the page has the open-loop table (every estimator on the scenario's recorded run);
closed-loop scenarios add a closed-loop table (one loop per estimator, `suite.run_closed_loops`)
with the closed-loop targets and a figure; scenarios whose ω0 schedule changes (omega_steps:
the adaptation benchmark; omega_schedule) add the adaptation table (`benchmark.adaptation`) and
a figure. Figures are PNGs in ``results/`` next to the page (the first held-out seed of each
scenario).
"""
from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
import datetime as dt
import json
import math
from pathlib import Path
import sys
import time
from typing import Any

import numpy as np

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.adaptation import FROZEN_RATIO, RECOVERY_WINDOWS, TOLERANCE
from lf_predictor_ros.benchmark.suite import ESTIMATORS, LOOP_ESTIMATORS, CaseResult, run_case
from lf_predictor_ros.core.evaluation import DOF_NAMES
from sim_ros.simulation import load_scenario

SUITE: dict[str, float | None] = {  # scenario → simulated duration [s] (None = scenario's own)
    'onedof_reference': 3600.0,
    'onedof_excited': 3600.0,
    'onedof_no_excitation': 3600.0,
    'onedof_feedback': 3600.0,
    'threedof_open_loop': 3600.0,
    'supply_closed_loop': 3600.0,
    'omega_schedule': None,
    'omega_steps': None,  # the adaptation benchmark (ω0 steps 1.25 → 0.3 → 1.25 rad/s)
}
FAST_SUITE: dict[str, float | None] = {'onedof_feedback': 600.0, 'supply_closed_loop': 600.0}
FAST_OVERRIDES = {'max_epochs': 15}  # smoke run only: fewer epochs per training
# issue 6: adaptive RMSE ≤ ratio × the reference estimator's, on every DOF
TARGETS = (('cascade', 0.5), ('observer', 1.0), ('observer_mistuned', 0.7))
# issue 6, closed loop: thrust wave-band power adaptive / raw; position RMSE adaptive / observer
THRUST_WAVE_POWER_RATIO = 0.10
POSITION_RMSE_RATIO = 1.2
FIGURE_DIR = 'results'  # next to the results page
EPS_TIME = 1e-6  # [s] 'just before' a change time (schedules are right-continuous at steps)


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='benchmark', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--fast', action='store_true', help='short smoke run (CI)')
    parser.add_argument('--seeds', type=int, default=3,
                        help='seeds 1..N per scenario, tuning seeds included (default 3)')
    parser.add_argument('--tuning-seeds', type=int, default=1,
                        help='how many of the seeds are tuning seeds (default 1)')
    parser.add_argument('--scenarios', nargs='*', help='subset of the suite')
    parser.add_argument('--duration', type=float, help='override every duration [s]')
    parser.add_argument('-o', '--output', default='docs/RESULTS.md', help='results page')
    parser.add_argument('--json', help='raw results (default runs/benchmark-<time>.json)')
    args = parser.parse_args(argv)
    if args.seeds < 1 or not 0 <= args.tuning_seeds < args.seeds:
        parser.error('need --seeds ≥ 1 and 0 ≤ --tuning-seeds < --seeds (held-out seeds ≥ 1)')
    return args


def _mean_rmse(cases: list[CaseResult], estimator: str) -> list[float]:
    values = [c.metrics[estimator].rmse for c in cases if estimator in c.metrics]
    return [float(np.mean(col)) for col in zip(*values, strict=True)] if values else []


def _format_value(value: float, dof: str) -> str:
    return f'{value:.4f}' if dof != 'yaw' else f'{value:.5f}'


def _scenario_table(name: str, cases: list[CaseResult]) -> list[str]:
    ndof = cases[0].ndof
    dofs = DOF_NAMES[:ndof]
    lines = [f'### {name}', '',
             f'{len(cases)} held-out seed(s): {", ".join(str(c.seed) for c in cases)}; '
             f'{cases[0].duration:.0f} s simulated, scored after {cases[0].warmup:.0f} s. '
             'RMSE of the LF estimate vs the true LF pose [m, m, rad]:', '',
             '| estimator | ' + ' | '.join(dofs) + ' |', '|---|' + '---|' * ndof]
    for est in ESTIMATORS:
        rmse = _mean_rmse(cases, est)
        if rmse:
            lines.append(f'| {est} | ' + ' | '.join(_format_value(v, d)
                                                    for v, d in zip(rmse, dofs, strict=True))
                         + ' |')
    adaptive = _mean_rmse(cases, 'adaptive')
    lines += ['', '| target (issue 6) | ' + ' | '.join(dofs) + ' | verdict |',
              '|---|' + '---|' * (ndof + 1)]
    for ref, bound in TARGETS:
        other = _mean_rmse(cases, ref)
        if not (adaptive and other):
            continue
        ratios = [a / o if o > 0 else math.inf for a, o in zip(adaptive, other, strict=True)]
        verdict = 'met' if all(r <= bound for r in ratios) else 'MISSED'
        lines.append(f'| adaptive / {ref} ≤ {bound} | ' + ' | '.join(f'{r:.2f}' for r in ratios)
                     + f' | {verdict} |')
    frozen = _mean_rmse(cases, 'frozen')
    if frozen and adaptive:
        lines.append('| frozen / adaptive (info) | ' + ' | '.join(
            f'{f / a:.2f}' for f, a in zip(frozen, adaptive, strict=True)) + ' | |')
    return lines + ['']


def _fmt(value: float) -> str:
    return f'{value:.3g}' if math.isfinite(value) else str(value)


def _loop_mean(cases: list[CaseResult], loop: str, key: str, dof: str | None = None) -> float:
    values = [c.closed_loop[loop][key] if dof is None else c.closed_loop[loop][key][dof]
              for c in cases if loop in c.closed_loop]
    return float(np.mean(values)) if values else math.nan


def _loop_max(cases: list[CaseResult], loop: str, key: str) -> float:
    values = [c.closed_loop[loop][key] for c in cases if loop in c.closed_loop]
    return float(np.max(values)) if values else math.nan


def _stability_cell(cases: list[CaseResult], loop: str) -> str:
    failures = [f'seed {c.seed}: {c.closed_loop[loop]["stability"]["reason"]}' for c in cases
                if loop in c.closed_loop and not c.closed_loop[loop]['stability']['stable']]
    return 'yes' if not failures else 'NO (' + '; '.join(failures) + ')'


def _ratio(numerator: float, denominator: float) -> float:
    return numerator / denominator if denominator > 0.0 else math.inf


def _verdict(ok: bool) -> str:
    return 'met' if ok else 'MISSED'


def _closed_loop_table(cases: list[CaseResult]) -> list[str]:
    ndof = cases[0].ndof
    dofs = DOF_NAMES[:ndof]
    loops = [name for name in LOOP_ESTIMATORS if any(name in c.closed_loop for c in cases)]
    lines = ['#### closed loop', '',
             'PID fed by each estimator; true LF pose vs setpoint and applied thrust after the '
             f'same warm-up ({cases[0].warmup:.0f} s). Means over the seeds (max excursion: the '
             'worst seed). Thrust wave-band power [N², N², (N·m)²] and total variation [N, N, '
             'N·m] per DOF (' + ', '.join(dofs) + ').', '',
             '| loop | position RMSE [m] | heading RMSE [rad] | max excursion [m] | '
             'thrust wave-band power | thrust total variation | stable |',
             '|---|---|---|---|---|---|---|']
    for loop in loops:
        heading = _loop_mean(cases, loop, 'heading_rmse') if ndof == 3 else math.nan
        power = ', '.join(_fmt(_loop_mean(cases, loop, 'thrust_wave_band_power', d))
                          for d in dofs)
        variation = ', '.join(_fmt(_loop_mean(cases, loop, 'thrust_total_variation', d))
                              for d in dofs)
        lines.append(f'| {loop} | {_fmt(_loop_mean(cases, loop, "position_rmse"))} | '
                     f'{_fmt(heading) if ndof == 3 else "–"} | '
                     f'{_fmt(_loop_max(cases, loop, "max_excursion"))} | {power} | {variation} '
                     f'| {_stability_cell(cases, loop)} |')
    return lines + [''] + _closed_loop_targets(cases, dofs)


def _closed_loop_targets(cases: list[CaseResult], dofs: Sequence[str]) -> list[str]:
    lines = ['| target (issue 6, closed loop) | value | verdict |', '|---|---|---|']
    runs = [c.closed_loop['adaptive']['stability']['stable'] for c in cases
            if 'adaptive' in c.closed_loop]
    if runs:
        lines.append(f'| adaptive loop stable (bounded, no limit cycle) in every seed | '
                     f'{sum(runs)}/{len(runs)} seeds | {_verdict(all(runs))} |')
    if all(any(n in c.closed_loop for c in cases) for n in ('adaptive', 'raw')):
        ratios = [_ratio(_loop_mean(cases, 'adaptive', 'thrust_wave_band_power', d),
                         _loop_mean(cases, 'raw', 'thrust_wave_band_power', d)) for d in dofs]
        lines.append(f'| thrust wave-band power adaptive / raw ≤ {THRUST_WAVE_POWER_RATIO:.2f} '
                     'per DOF | ' + ', '.join(f'{d} {r:.3f}' for d, r in zip(dofs, ratios,
                                                                              strict=True))
                     + f' | {_verdict(all(r <= THRUST_WAVE_POWER_RATIO for r in ratios))} |')
    adaptive = _loop_mean(cases, 'adaptive', 'position_rmse')
    for ref, bound in (('observer', POSITION_RMSE_RATIO), ('ideal', None)):
        if not any(ref in c.closed_loop for c in cases) or math.isnan(adaptive):
            continue
        ratio = _ratio(adaptive, _loop_mean(cases, ref, 'position_rmse'))
        if bound is None:
            lines.append(f'| position RMSE adaptive / {ref} (info) | {ratio:.2f} | |')
        else:
            lines.append(f'| position RMSE adaptive / {ref} ≤ {bound} | {ratio:.2f} | '
                         f'{_verdict(ratio <= bound)} |')
    return lines + ['']


def _adaptation_table(cases: list[CaseResult]) -> list[str]:
    window = float(cases[0].info['params']['retrain_period'])
    schedule = load_scenario(cases[0].scenario).waves.peak_freq
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
        for i, event in enumerate(events):
            following = events[i + 1].time if i + 1 < len(events) else case.duration
            before, after = schedule(event.time - EPS_TIME), schedule(following - EPS_TIME)
            lines.append(f'| {case.seed} | {event.time:.0f} | {before:.2f} → {after:.2f} | '
                         f'{_fmt(event.steady_rmse)} | '
                         f'{_fmt(event.adaptive_rmse_after)} | {_fmt(event.frozen_rmse_after)} '
                         f'| {_fmt(event.recovery_time)} | {_fmt(event.frozen_ratio)} |')
            recoveries.append(event.recovery_time)
            ratios.append(event.frozen_ratio)
    back = sum(r <= limit for r in recoveries)
    lines += ['', '| target (issue 6, adaptation) | value | verdict |', '|---|---|---|',
              f'| adaptive back within {TOLERANCE}× steady RMSE within 2Δ = {limit:g} s after '
              f'every change | {back}/{len(recoveries)} changes | '
              f'{_verdict(bool(recoveries) and back == len(recoveries))} |',
              f'| frozen ≥ {FROZEN_RATIO:g}× adaptive RMSE over the 2Δ after every change | '
              f'min {_fmt(min(ratios, default=math.nan))} | '
              f'{_verdict(bool(ratios) and min(ratios) >= FROZEN_RATIO)} |', '']
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


def write_figures(results: list[CaseResult], tuning: set[int], page: Path,
                  ) -> dict[str, list[str]]:
    """PNGs of the first held-out seed of each scenario next to the page; links per scenario."""
    from lf_predictor_ros.benchmark.plots import plot_adaptation, plot_closed_loops

    folder = page.parent / FIGURE_DIR
    links: dict[str, list[str]] = {}
    for case in results:
        if case.seed in tuning or case.scenario in links:
            continue
        links[case.scenario] = []
        if case.loop_series:
            folder.mkdir(parents=True, exist_ok=True)
            name = f'{case.scenario}_closed_loop.png'
            plot_closed_loops(f'{case.scenario}, seed {case.seed}: closed loops',
                              case.loop_series, case.ndof, folder / name)
            links[case.scenario].append(f'{FIGURE_DIR}/{name}')
        if case.adaptation_series is not None:
            folder.mkdir(parents=True, exist_ok=True)
            name = f'{case.scenario}_adaptation.png'
            plot_adaptation(f'{case.scenario}, seed {case.seed}: rolling RMSE of the LF '
                            'estimate, adaptive vs frozen', case.adaptation_series,
                            folder / name, 'm')
            links[case.scenario].append(f'{FIGURE_DIR}/{name}')
    return links


def render(results: list[CaseResult], tuning: set[int], command: str, wall: float,
           figures: Mapping[str, Sequence[str]] | None = None) -> str:
    """The results page (markdown); ``figures`` maps a scenario to its image links."""
    lines = ['# Results: adaptive LF predictor vs classical wave filters', '',
             f'Generated by `{command}` on {dt.date.today().isoformat()} in {wall:.0f} s wall '
             '(2-core machine). Regenerate with the same command.', '',
             'Estimators (see `lf_predictor_ros/benchmark/suite.py`): adaptive = the product; '
             "frozen = trained once (the thesis's static network); cascade = causal notch + "
             'low-pass at the true ω0; observer = passive observer with the true model and ω0; '
             'observer_mistuned = M ×1.3, D ×0.7, ω0 ×1.2; smoother = zero-phase (non-causal '
             'reference); raw = the measurement. The first table of each scenario is open loop '
             'on the recorded data of the scenario (the closed-loop scenarios are recorded with '
             'the PID on the true LF pose). Closed-loop scenarios then run the PID once per '
             'estimator, that estimator in the loop (same seed: same waves and noise; the '
             'estimator called every h = 1 s, its output held in between), plus `ideal` (PID on '
             'the true LF pose); the smoother is non-causal and cannot be in a loop. '
             + _stability_rule(), '',
             f'Tuning seeds (not in the tables): {sorted(tuning) or "none"}.', '',
             'What the numbers say, and why the MISSED targets are missed: '
             '`docs/BENCHMARKS.md`, "Scenario suite summary".', '']
    by_scenario: dict[str, list[CaseResult]] = {}
    for case in results:
        if case.seed not in tuning:
            by_scenario.setdefault(case.scenario, []).append(case)
    for name, cases in by_scenario.items():
        lines += _scenario_table(name, cases)
        if any(c.closed_loop for c in cases):
            lines += _closed_loop_table(cases)
        if any(c.adaptation for c in cases):
            lines += _adaptation_table(cases)
        for link in (figures or {}).get(name, ()):
            lines += [f'![{name}]({link})', '']
    return '\n'.join(lines) + '\n'


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `benchmark` executable."""
    args = _parse(argv)
    suite = FAST_SUITE if args.fast else SUITE
    names = args.scenarios or list(suite)
    unknown = [n for n in names if n not in SUITE and n not in FAST_SUITE]
    if unknown:
        print(f'benchmark: unknown scenario(s) {unknown}; the suite is {list(SUITE)}',
              file=sys.stderr)
        return 2
    all_seeds = list(range(1, 2 if args.fast else args.seeds + 1))
    tuning = set() if args.fast else set(all_seeds[:args.tuning_seeds])
    seeds = [s for s in all_seeds if s not in tuning]  # tuning seeds are never scored here
    start = time.monotonic()
    results: list[CaseResult] = []
    for name in names:
        duration = args.duration or suite.get(name, SUITE.get(name))
        for seed in seeds:
            t0 = time.monotonic()
            case = run_case(name, seed, duration=duration,
                            params_overrides=FAST_OVERRIDES if args.fast else None)
            results.append(case)
            print(f'[benchmark] {name} seed {seed}: {time.monotonic() - t0:.1f} s', flush=True)
    wall = time.monotonic() - start
    command = 'benchmark ' + ' '.join(argv if argv is not None else sys.argv[1:])
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    figures = write_figures(results, tuning, Path(args.output))
    page = render(results, tuning, command.strip(), wall, figures)
    Path(args.output).write_text(page, encoding='utf-8')
    raw_path = Path(args.json or f'runs/benchmark-{dt.datetime.now():%Y%m%d-%H%M%S}.json')
    raw_path.parent.mkdir(parents=True, exist_ok=True)
    payload: dict[str, Any] = {'command': command, 'wall_seconds': wall,
                               'tuning_seeds': sorted(tuning),
                               'cases': [c.to_dict() for c in results]}
    raw_path.write_text(json.dumps(payload, indent=1, default=float), encoding='utf-8')
    print(page)
    print(f'[benchmark] wrote {args.output} and {raw_path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
