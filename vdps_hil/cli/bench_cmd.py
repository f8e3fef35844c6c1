"""``vdps bench``: the hardware-in-the-loop bench (``vdps_hil.hil``): the simulated vehicle
sends its sensors on CAN and serial ports paced to the wall clock, the live pipeline answers
with VDPS_Warning on CAN, a simulated ECU reacts, and everything is timed."""

from __future__ import annotations

import math
import sys

import click

from vdps_hil.cli.common import UserError, json_option, live_server, serve_option, write_json
from vdps_hil.hil.scheduling import DEFAULT_PRIORITY as DEFAULT_RT_PRIORITY, NOT_ASKED

_EXAMPLE = """\b
Examples:
  vdps bench --react -o bench.mcap
  vdps bench --react -o bench.mcap --serve 8765   # watch it live in Foxglove (ws://127.0.0.1:8765)
  vdps bench --scenario paper-left-turn --duration 12 --json -
  vdps bench --can pty --speed 0.5          # pipeline in its own process, slcan on a pty
  vdps bench --can virtual                  # everything in one process (python-can virtual bus)
  vdps bench --can socketcan:vcan0          # a Linux vcan (sudo ip link add dev vcan0 type vcan)

\b
--can SPEC: tcp (default; with --serve: virtual): the simulator as a socketcand server on
127.0.0.1 only, the pipeline in a child process; virtual (one process, python-can's virtual
bus; serial on ptys); pty (simulator as an slcan adapter on a pseudo-terminal, pipeline in a
child process),
or a python-can interface string INTERFACE:CHANNEL[,key=value...] opened by both sides
(socketcan:vcan0; with --sim-can the simulator opens another interface, e.g. two USB
adapters wired together: --can pcan:PCAN_USBBUS1 --sim-can kvaser:0).

\b
ECU reaction (--react): after the first valid VDPS_Warning with level >= 2, 100 ms dead time,
drive torque cut, brake pressure 0 -> full in 300 ms, 2500 N m per wheel on all four wheels.

\b
Headroom: before the run the bench runs itself briefly at 0.5x and measures the CPU its
simulator and pipeline spend per simulated second on this machine (vdps_hil.hil.headroom);
below 1x it refuses (exit 2), below 2x it warns; the summary states it; --speed auto runs at
the fastest speed with 2x headroom (at most 1x). A pipeline that falls behind skips its own work, counts it and says "sensor
missing" in its warnings rather than accumulating lag."""


@click.command("bench", epilog=_EXAMPLE)
@click.option("--scenario", default="fishhook-suv", show_default=True, metavar="NAME",
              help="Scenario (configs/scenarios/NAME.toml or a .toml path).")
@click.option("--vehicle", default=None, metavar="FILE",
              help="Truth vehicle file or name for the simulator (default: the scenario's).")
@click.option("--model", default=None, metavar="FILE",
              help="Model vehicle file for the pipeline (default: the truth file's pair, e.g. suv-model), "
                   "or a saved workbench model (vdps diagnose --save-model).")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Switch on an effect in the simulator (NAME or NAME:param=value,...); repeatable.")
@click.option("--fault", "faults", multiple=True, metavar="NAME",
              help="Inject a sensor/wire fault (NAME or NAME:key=value,...); repeatable.")
@click.option("--duration", "duration_s", type=float, default=None, metavar="S",
              help="Simulated seconds (default: the scenario's).")
@click.option("--speed", default="1", show_default=True,
              metavar="X|auto",
              help="Simulated seconds per wall second; auto: the fastest speed with 2x measured headroom on "
                   "this machine, at most 1 (see Headroom below).")
@click.option("--can", "can_spec", default=None, metavar="SPEC",
              help="CAN transport (see below) [default: tcp, with --serve virtual].")
@click.option("--sim-can", "sim_can", default=None, metavar="SPEC",
              help="Interface the simulator opens when --can is an interface string (default: the same).")
@click.option("--react/--no-react", default=False, show_default=True,
              help="Let the simulated ECU cut torque and brake on a warning.")
@click.option("--seed", type=click.IntRange(0, None), default=0, show_default=True, help="Seed of every sensor's random streams.")
@click.option("--profile", default=None, metavar="NAME", help="Sensor profile [default: table1-susp1k].")
@click.option("-o", "--output", default=None, metavar="FILE.mcap",
              help="Record the session: raw topics as the pipeline received them, /decoded, /est, /truth.")
@click.option("--params", default=None, metavar="FILE",
              help="Start the pipeline from saved identified parameters (vdps replay --save-params): "
                   "warnings valid at once, unless the file had not settled the cornering stiffnesses "
                   "[default: the model file's priors, warnings valid once the cornering stiffnesses "
                   "converge].")
@click.option("--calibrate", "calibrate_on", default=None, metavar="SCENARIO",
              help="First drive SCENARIO (e.g. paper) with the same vehicle, offline, replay it with the "
                   "identifier and start the pipeline from the parameters it identified (as --params).")
@click.option("--quiet", is_flag=True, help="No live status line.")
@click.option("--headroom-check/--no-headroom-check", "headroom_check", default=True, show_default=True,
              help="Measure the headroom before the run and refuse a run below 1x (see below).")
@click.option("--rt-priority", "rt_priority", type=click.IntRange(0, 99), default=DEFAULT_RT_PRIORITY,
              show_default=True, metavar="N",
              help="Run the simulator and the pipeline under SCHED_FIFO at priority N while the bench runs, "
                   "when the system permits it (else the default policy, said in the summary); 0: off.")
@json_option
@serve_option
def bench(scenario, vehicle, model, effects, faults, duration_s, speed, can_spec, sim_can, react, seed, profile,
          output, params, calibrate_on, quiet, headroom_check, rt_priority, json_out, serve_port):
    """Run the hardware-in-the-loop bench on one machine with nothing plugged in: the simulated
    vehicle on CAN and serial ports in real time, the live pipeline, its warning on CAN, a
    simulated ECU. Prints what happened: warning time, lead time, ECU action, upright or not."""
    import tempfile
    from dataclasses import replace
    from pathlib import Path

    from vdps_hil.hil.bench import Bench
    from vdps_hil.hil.bench_config import BenchConfig, BenchError, calibrate

    if output is not None:
        out = Path(output)
        if out.is_dir():
            raise UserError(f"-o {output}: is a directory")
        if not out.parent.exists():
            raise UserError(f"-o {output}: directory {out.parent} does not exist")
    if calibrate_on is not None and params is not None:
        raise UserError("give --params or --calibrate, not both")
    speed = _parse_speed(speed)
    if can_spec is None:
        can_spec = "virtual" if serve_port is not None else "tcp"
    cal = None
    tmp = tempfile.TemporaryDirectory(prefix="vdps-bench-cal-")
    try:
        cfg = BenchConfig(scenario=scenario, vehicle=vehicle, model=model, effects=tuple(effects),
                          faults=tuple(faults), duration_s=duration_s, speed=1.0 if speed == "auto" else speed,
                          can=can_spec, sim_can=sim_can,
                          react=react, output=output, seed=seed, profile=profile, params=params,
                          rt_priority=rt_priority)
        b = Bench(cfg)
        if calibrate_on is not None:
            if not quiet:
                click.echo(f"calibration: simulating '{calibrate_on}' with {b.truth_vehicle} and identifying "
                           f"its parameters (offline) ...", err=True)
            cal = calibrate(calibrate_on, b.truth_vehicle, b.model, tmp.name, profile=profile, seed=seed + 1000)
            b = Bench(replace(cfg, params=cal["params"]))
    except (BenchError, ValueError) as e:
        tmp.cleanup()
        raise UserError(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
    to_stderr = json_out == "-"
    if serve_port is not None and (output is None or b.transport.cross_process):
        tmp.cleanup()
        raise UserError("--serve serves the -o recording of a pipeline in this process: give -o, --can virtual")
    try:
        if speed == "auto":
            if not headroom_check:
                raise UserError("--speed auto needs the headroom measurement: drop --no-headroom-check")
            b = _auto_speed(b, replace(b.config), quiet)
        if headroom_check:
            _check_headroom(b)
    except BenchError as e:
        tmp.cleanup()
        raise UserError(f"headroom measurement: {str(e).splitlines()[0]}") from None
    except UserError:
        tmp.cleanup()
        raise
    status = None if quiet else _StatusLine(sys.stderr)
    try:
        with live_server(serve_port, wait=False) as live:
            b.mirror = None if live is None else live.mirror
            result = b.run(status)
    except BenchError as e:
        if status is not None:
            status.end()
        raise UserError(str(e).splitlines()[0]) from None
    if status is not None:
        status.end()
    doc = result.to_json()
    tmp.cleanup()
    if cal is not None:
        conv = ", ".join(k for k, v in cal["converged"].items() if v) or "none"
        doc["calibration"] = {k: v for k, v in cal.items() if k != "params"}
        click.echo(f"calibration: pipeline started from the parameters identified on '{cal['scenario']}' "
                   f"(seed {cal['seed']}, {cal['cpu_s']:.1f} s CPU; converged: {conv})", err=to_stderr)
    for line in describe(doc):
        click.echo(line, err=to_stderr)
    write_json(doc, json_out)


MAX_SPEED = 1000.0
"""Fastest ``--speed`` taken: ten times what the simulator itself reaches (physics, sensors, wire
encoding: about 100x real time, tools/bench_sim.py)."""


def _parse_speed(value) -> float | str:
    """``--speed``: a positive number or ``auto`` (one-line error otherwise)."""
    text = str(value).strip().lower()
    if text == "auto":
        return "auto"
    try:
        x = float(text)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x > 0):
        raise UserError(f"--speed must be a positive number or 'auto', got {value!r}")
    if x > MAX_SPEED:  # 1e9 left the pipeline process waiting past the bench's stop (an error after 60 s)
        raise UserError(f"--speed must be at most {MAX_SPEED:g} (the simulator runs about 100x real time), got {value!r}")
    return x


def _auto_speed(b, cfg, quiet: bool):
    """``--speed auto``: measure the headroom at 1x and return the bench at the speed with
    ``WARN_BELOW`` headroom, at most 1x (its measurement kept, restated at that speed)."""
    from dataclasses import replace

    from vdps_hil.hil.bench import Bench

    h = b.measure_headroom()
    speed = float(f"{min(1.0, h.supported_speed):.2g}")
    nb = Bench(replace(cfg, speed=speed))
    nb.headroom = replace(h, speed=speed)
    if not quiet:
        click.echo(f"vdps bench: --speed auto: {speed:g}x ({nb.headroom.describe()})", err=True)
    return nb


def _check_headroom(b) -> None:
    """Measure the bench's headroom (``hil.headroom``; unless ``--speed auto`` measured it):
    refuse below REFUSE_BELOW (one line, exit 2), warn below WARN_BELOW."""
    from vdps_hil.hil.headroom import REFUSE_BELOW, WARN_BELOW

    h = b.headroom if b.headroom is not None else b.measure_headroom()
    verdict = h.verdict()
    if verdict == "refuse":
        raise UserError(f"{h.describe()}: below {REFUSE_BELOW:g}x the pipeline cannot keep up; run at "
                        f"--speed {h.supported_speed:.2g} (or --speed auto) or give --no-headroom-check")
    if verdict == "warn":
        click.echo(f"vdps bench: warning: {h.describe()}, below {WARN_BELOW:g}x: the pipeline may miss "
                   f"deadlines (skipped work is counted and its warnings say 'sensor missing')", err=True)


class _StatusLine:
    """One live line on a terminal (rewritten in place), or a line per second elsewhere."""

    def __init__(self, stream):
        self.stream = stream
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self._last = -1.0
        self._width = 0

    def __call__(self, d: dict) -> None:
        ev = ", ".join(e.replace("_", " ") for e in d["events"]) or "upright"
        warn = (f"warning L{d['warning_level']} since {d['first_warning_t_s']:.2f} s"
                if d["first_warning_t_s"] is not None else "no warning")
        brake = f" | ECU brake {100 * d['brake_fraction']:.0f} %" if d["brake_fraction"] > 0 else ""
        line = (f"t {d['t_s']:5.2f}/{d['duration_s']:.2f} s | CAN {d['frames_received']}/{d['frames_sent']} "
                f"IMU {d['imu_bytes_received'] // 47}/{d['imu_bytes_sent'] // 47} | late sends {d['late_sends']} | "
                f"roll {d['roll_deg']:+5.1f} deg | {warn}{brake} | {ev}")
        if self.tty:
            pad = max(0, self._width - len(line))
            self.stream.write("\r" + line + " " * pad)
            self.stream.flush()
            self._width = len(line)
        elif d["final"] or math.floor(d["t_s"]) > self._last:
            self._last = math.floor(d["t_s"])
            self.stream.write(line + "\n")
            self.stream.flush()

    def end(self) -> None:
        if self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()


def _t(x) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.2f} s"


def describe(d: dict) -> list[str]:
    """The plain-words summary of a bench run (what ``make run`` prints)."""
    tr = {"virtual": "one process, python-can virtual bus + IMU and GNSS on pseudo-terminals",
          "pty": "pipeline in its own process; CAN as slcan on a pseudo-terminal, IMU and GNSS on ptys",
          "tcp": "pipeline in its own process; CAN over TCP on 127.0.0.1 (socketcand), IMU and GNSS on ptys",
          "external": f"CAN on {d['can'].get('pipeline_spec')}, IMU and GNSS on pseudo-terminals"}[d["transport"]]
    lines = [f"vdps bench: {d['scenario']} ({d['vehicle']} simulated, pipeline on {d['model']}), {tr}, "
             f"speed {d['speed']:g}x, ECU reaction {'on' if d['react'] else 'off'}"]
    lost = d["dropped"]
    stopped = " (interrupted: the drive ended there)" if d.get("stop_reason") == "interrupted" else ""
    lines.append(f"  ran {d['duration_s']:.2f} s of simulated time{stopped} in {d['wall_time_s']:.2f} s "
                 f"({d['realtime_factor']:.2f}x real time); sent {d['frames_sent']} CAN frames, "
                 f"{d['imu_packets_sent']} IMU packets, {d['lines_sent']} NMEA lines; "
                 + ("the pipeline received every one of them" if lost == 0 else f"{lost} were LOST on the way")
                 + f"; {d['late_sends']} of {d['sends']} sends later than {d['late_tolerance_ms']:g} ms")
    ref = d["lead_reference"] == "open_loop"
    if d["first_warning_t_s"] is None or not math.isfinite(d["first_warning_t_s"]):
        ws = d.get("warning_status") or {}
        why = ""
        if not ws.get("valid") and ws.get("not_converged", 0) >= max(1, ws.get("sensor_missing", 0)):
            waits = ", ".join((d.get("predictions") or {}).get("require_converged") or ()) or "the identification"
            why = (f"; no frame was valid: 'not converged' in {ws['not_converged']} of {sum(ws.values())} warning "
                   f"cycles (the warning waited for {waits}: from the model file's priors, or a parameter file "
                   "that had not settled it; [warning] require_converged and converged_hold_s)")
        lines.append("  warning: none -- the pipeline never sent a valid VDPS_Warning of level >= 2" + why)
    else:
        lt = d["warning_lead_time_s"]
        ponr = d["point_of_no_return_t_s"]
        when = "without the ECU's reaction, " if ref else ""
        lead = (f"{lt:.2f} s before the point of no return ({when}at {ponr:.2f} s)"
                if math.isfinite(lt if lt is not None else math.nan) else "no point of no return to lead")
        tip = d["warning_lead_to_tipup_s"]
        tip_s = (f" and {tip:.2f} s before tip-up (at {d['tip_up_t_s']:.2f} s)"
                 if tip is not None and math.isfinite(tip) else "")
        lines.append(f"  warning: first VDPS_Warning of level >= 2 on the bus at {d['first_warning_t_s']:.2f} s: "
                     f"{lead}{tip_s}")
    e = d["ecu"]
    if not d["react"]:
        lines.append(f"  ECU: listening only (--no-react); it accepted {e['frames']['accepted']} warning frames "
                     f"(CRC and counter checked), {e['frames']['timeouts']} timeouts")
    elif e["intervention_t_s"] is None:
        lines.append("  ECU: no intervention (no valid warning of level >= 2 arrived)")
    else:
        a = e["actuator"]
        lines.append(f"  ECU: acted on the warning at {e['intervention_t_s']:.2f} s: cut the drive torque and "
                     f"started braking at {e['actuation_t_s']:.2f} s ({1000 * a['delay_s']:.0f} ms dead time), "
                     f"full brakes ({a['brake_torque_full_nm_per_wheel']:.0f} N m per wheel) at "
                     f"{e['full_brake_t_s']:.2f} s")
    if d["rolled_over"]:
        lines.append(f"  outcome: the vehicle ROLLED OVER (point of no return at {_t(d['point_of_no_return_t_s'])}, "
                     f"max roll {d['max_abs_roll_deg']:.1f} deg relative to the road)")
    else:
        tipped = any(ev.get("kind") == "tip_up" for ev in d["truth_events"])
        extra = ""
        if ref:
            extra = f"; without the ECU it would have rolled over at {_t(d['point_of_no_return_t_s'])}"
        lines.append(f"  outcome: the vehicle stayed upright{' (after lifting two wheels)' if tipped else ''}, "
                     f"max roll {d['max_abs_roll_deg']:.1f} deg relative to the road{extra}")
    w = d["warning_latency_ms"]
    lines.append(f"  latency from sensor frame to pipeline output on the bus: p50 {w['p50']:.1f} ms, "
                 f"p99 {w['p99']:.1f} ms over {d['output_cycles']} pipeline cycles"
                 + ("" if d["pipeline_keeps_up"] else " -- the pipeline did NOT keep up at this speed"))
    lines += _health_lines(d)
    sc = d.get("scheduling")
    if sc and sc.get("policy") == "fifo":
        lines.append(f"  scheduling: SCHED_FIFO priority {sc['priority']} (simulator and pipeline)")
    elif sc and sc.get("reason") != NOT_ASKED:
        lines.append(f"  scheduling: default time sharing ({sc.get('reason')}); a CPU-bound process beside the "
                     f"bench then adds latency")
    if d["output"]:
        lines.append(f"  recording: {d['output']} (raw CAN/serial as the pipeline received them, /decoded, /est, "
                     f"/truth)")
    return lines


def _health_lines(d: dict) -> list[str]:
    """What made work late or frames non-valid (each a counted mechanism) and the headroom."""
    lines: list[str] = []
    m = d.get("deadline_misses") or {}
    if m.get("samples"):
        lines.append(f"  deadline misses: the pipeline fell more than {m['deadline_ms']:g} ms behind "
                     f"{m['episodes']} time(s) and skipped {m['samples']} samples (first at {m['first_t_s']:.2f} s); "
                     f"its warnings said 'sensor missing' meanwhile")
    pr = d.get("predictions") or {}
    if pr.get("dropped") or pr.get("failed"):
        lines.append(f"  predictions: {pr.get('dropped', 0)} of {pr.get('started', 0)} dropped at their deadline "
                     f"({1e3 * pr.get('latency_s', 0.0):g} ms of bus time), {pr.get('failed', 0)} failed; "
                     f"the warning frames said 'fault' until the next prediction was used")
    from vdps_hil.cli.replay_cmd import params_line, predictor_params_line

    line = predictor_params_line({"prediction": pr})  # identification.trusted: what the predictor had
    if line:
        lines.append(line)
    line = params_line({**d, "prediction": pr})  # what --params had not settled, and what the warning waited for
    if line:
        lines.append(line)
    un = d.get("warning_unhealthy") or {}
    if un.get("inconsistent"):
        cycles = sum((d.get("warning_status") or {}).values())
        lines.append(f"  estimate consistency: the innovation monitor found the estimate inconsistent with the fixes "
                     f"in {un['inconsistent']} of {cycles} warning cycles; their frames said 'fault'")
    h = d.get("headroom")
    if h:
        lines.append(f"  headroom: {h['headroom']:.1f}x at speed {h['speed']:g}x (measured before the run: simulator "
                     f"{1e3 * h['simulator_cost_s_per_s']:.0f} ms + pipeline {1e3 * h['pipeline_cost_s_per_s']:.0f} ms "
                     f"of CPU per simulated second in a probe run of the bench)")
    return lines
