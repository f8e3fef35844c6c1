"""The Foxglove layout shipped in ``configs/foxglove/vdps-layout.json``: the dashboard an engineer
opens on a replay output, a bench recording or a live ``--serve`` run (Foxglove: Layouts ->
Import from file).

Built with the foxglove-sdk's own layout types (``foxglove.layouts``), so its JSON is the format
Foxglove imports; ``tools/foxglove_layout.py`` writes the file and a test holds the shipped file
equal to :func:`build_layout` and every plotted path to a topic and field a replay writes.

====================  ==========================================================================
tab                   panels (topics: ``app.est_topics``, ``app.foxglove_view``)
====================  ==========================================================================
Rollover              roll angles (absolute, relative to the road, road bank; predicted peak),
                      LTR (predicted peak, the warning frame's), warning level and status
                      (indicators and a step plot), time to rollover
Speeds                ENU velocity, GNSS speed, wheel speeds (filtered and decoded), steering
Innovations           NIS per measurement kind with its gate, accepted flags
Parameters            the ten identified parameters (eq 20-23), each with its 1-sigma on a
                      second axis, and the identifiability figures
Map / 3D              ``/gnss/fix`` and the estimated track ``/est/fix`` on the map; the pose
                      ``/est/tf`` (frame ``vehicle`` in ``enu``) in the 3D panel
====================  ==========================================================================

Angles are plotted in radians as recorded (SI inside; the labels carry the unit).
"""

from __future__ import annotations

import re
from pathlib import Path

import foxglove.layouts as fl

from vdps_hil.estimation.observations import ObsKind
from vdps_hil.model.params import CONFIG_DIR, PARAM_NAMES
from vdps_hil.record import schemas as S

__all__ = ["LAYOUT_PATH", "build_layout", "layout_json", "plotted_paths"]

LAYOUT_PATH: Path = CONFIG_DIR / "foxglove" / "vdps-layout.json"
"""The shipped layout file."""

WARNING_LEVEL_COLORS = ("#2e7d32", "#f9a825", "#ef6c00", "#c62828")
"""Indicator colours of warning levels 0..3 (none, caution, warning, imminent)."""

WARNING_STATUS_LABELS = ("valid", "not converged", "sensor missing", "fault")
"""``warning_status`` 0..3 (README, wire formats)."""

_SIGMA_AXIS = "sigma"


def _series(path: str, label: str, *, step: bool = False, axis: str | None = None) -> fl.PlotSeries:
    return fl.PlotSeries(value=path, label=label, enabled=True, timestamp_method="receiveTime",
                         line_interpolation="step" if step else None, y_axis_id=axis)


def _plot(title: str, series: list[fl.PlotSeries], y_label: str, sigma_label: str | None = None) -> fl.PlotPanel:
    axes = None if sigma_label is None else [fl.PlotSecondaryAxis(id=_SIGMA_AXIS, label=sigma_label)]
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=series, y_axis_label=y_label, show_legend=True, legend_display="floating", is_synced=True,
        x_axis_val="timestamp", secondary_axes=axes))


def _column(*panels, proportions=None) -> fl.SplitContainer:
    props = proportions or (1,) * len(panels)
    return fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=p, content=c)
                                                         for p, c in zip(props, panels)])


def _row(*panels) -> fl.SplitContainer:
    return fl.SplitContainer(direction="row", items=[fl.SplitItem(content=c) for c in panels])


def _indicator(title: str, path: str, labels, colors) -> fl.IndicatorPanel:
    rules = [fl.IndicatorRule(operator="=", raw_value=str(i), color=c, label=lab)
             for i, (lab, c) in enumerate(zip(labels, colors))]
    return fl.IndicatorPanel(title=title, config=fl.IndicatorConfig(
        path=path, style="background", rules=rules, fallback_color="#757575", fallback_label="no warning frame"))


def _rollover_tab() -> fl.SplitContainer:
    st, pr, wf = "/est/state.values", "/est/prediction.values", "/est/warning.fields"
    roll = _plot("Roll", [_series(f"{st}.phi_g_rad", "roll phi_g (absolute)"),
                          _series(f"{st}.phi_v_rad", "roll phi_v (relative to the road, eq 4)"),
                          _series(f"{st}.phi_r_rad", "road bank phi_r"),
                          _series(f"{pr}.peak_roll_rad", "predicted peak roll")], "rad")
    ltr = _plot("Load transfer ratio", [_series(f"{pr}.peak_ltr", "predicted peak LTR"),
                                        _series(f"{wf}.warning_ltr", "LTR in VDPS_Warning", step=True)], "LTR")
    level = _plot("Warning level and status", [_series(f"{wf}.warning_level", "level", step=True),
                                               _series(f"{wf}.warning_status", "status", step=True)], "code")
    ttr = _plot("Time to rollover", [_series(f"{wf}.warning_time_to_rollover_s", "in VDPS_Warning", step=True),
                                     _series(f"{pr}.time_to_point_of_no_return_s", "to the point of no return"),
                                     _series(f"{pr}.time_to_tip_up_s", "to tip-up")], "s")
    lights = _row(_indicator("Warning level", f"{wf}.warning_level", ("none", "caution", "warning", "imminent"),
                             WARNING_LEVEL_COLORS),
                  _indicator("Warning status", f"{wf}.warning_status", WARNING_STATUS_LABELS,
                             ("#2e7d32", "#f9a825", "#ef6c00", "#c62828")))
    return _row(_column(roll, ltr), _column(lights, level, ttr, proportions=(1, 2, 2)))


def _speeds_tab() -> fl.SplitContainer:
    st, fil = "/est/state.values", "/est/filtered.values"
    vel = _plot("Velocity", [_series(f"{st}.xdot_g_mps", "x_dot (East)"), _series(f"{st}.ydot_g_mps", "y_dot (North)"),
                             _series(f"{st}.zdot_g_mps", "z_dot (Up)"),
                             _series("/decoded/gnss/gnss_vel.fields.gnss_speed_mps", "GNSS speed")], "m/s")
    wheels = _plot("Wheel speeds", [_series(f"{fil}.wheel_speed_radps_{i}", f"wheel {i} (filtered)")
                                    for i in range(1, 5)], "rad/s")
    steer = _plot("Steering and torque", [_series(f"{fil}.steer_wheel_angle_rad", "steering wheel angle [rad]")]
                  + [_series(f"{fil}.wheel_torque_nm_{i}", f"torque {i} [N m]", axis=_SIGMA_AXIS) for i in range(1, 5)],
                  "rad", sigma_label="N m")
    return _column(vel, wheels, steer)


def _innovations_tab() -> fl.SplitContainer:
    kinds = [k.value for k in ObsKind]
    nis = _plot("NIS (chi-square gate dashed)", [
        s for k in kinds for s in (_series(f"/est/innovation/{k}.values.nis", k),
                                   fl.PlotSeries(value=f"/est/innovation/{k}.values.gate", label=f"{k} gate",
                                                 enabled=True, timestamp_method="receiveTime", line_style="dashed"))],
        "NIS")
    accepted = _plot("Accepted updates", [_series(f"/est/innovation/{k}.values.accepted", k, step=True)
                                          for k in kinds], "1 accepted, 0 not")
    return _column(nis, accepted, proportions=(2, 1))


_PARAM_GROUPS = (("Mass (eq 20)", ("mass_kg",), "kg"),
                 ("Tracking stiffness (eq 21)", tuple(f"tracking_stiffness_{i}_n" for i in range(1, 5)), "N"),
                 ("Cornering stiffness (eq 22)", ("cornering_stiffness_front_nprad", "cornering_stiffness_rear_nprad"),
                  "N/rad"),
                 ("Inertia (eq 23)", ("inertia_x_kgm2", "inertia_y_kgm2", "inertia_z_kgm2"), "kg m^2"))


def _parameters_tab() -> fl.SplitContainer:
    grouped = {n for _, names, _ in _PARAM_GROUPS for n in names}
    if grouped != set(PARAM_NAMES):  # the ten parameters, each plotted once
        raise AssertionError(f"layout parameter groups {sorted(grouped)} != {sorted(PARAM_NAMES)}")
    plots = [_plot(title, [s for n in names for s in (_series(f"/est/ident.values.{n}", n),
                                                      _series(f"/est/ident.sigmas.{n}", f"{n} 1-sigma",
                                                              axis=_SIGMA_AXIS))], unit, sigma_label=f"1-sigma [{unit}]")
             for title, names, unit in _PARAM_GROUPS]
    ident = _plot("Identifiability (min eigenvalue, Table 3) and convergence",
                  [_series(f"/est/ident.values.identifiability_{p}", p) for p in ("mass", "tracking", "cornering",
                                                                                  "inertia")]
                  + [_series(f"/est/ident.values.converged_{p}", f"{p} converged", step=True, axis=_SIGMA_AXIS)
                     for p in ("mass", "tracking", "cornering", "inertia")], "identifiability", sigma_label="converged")
    return _column(_row(plots[0], plots[1]), _row(plots[2], plots[3]), ident)


def _map_tab() -> fl.SplitContainer:
    track = fl.MapTopicSettings(history_mode="all", point_display_mode="dot", point_size=3)
    gmap = fl.MapPanel(title="Track", config=fl.MapConfig(
        follow_topic=S.EST_FIX_TOPIC, layer="map", zoom_level=17,
        topic_colors={S.GNSS_FIX_TOPIC: "#1565c0", S.EST_FIX_TOPIC: "#c62828"},
        topic_config={S.GNSS_FIX_TOPIC: track, S.EST_FIX_TOPIC: track}))
    scene = fl.ThreeDeePanel(title="Pose", config=fl.ThreeDeeConfig(
        follow_tf=S.VEHICLE_FRAME, fixed_frame=S.ENU_FRAME, follow_mode="follow-heading", enu_frame_id=S.ENU_FRAME,
        location_fix_topic=S.EST_FIX_TOPIC))
    return _row(gmap, scene)


def build_layout() -> fl.Layout:
    """The dashboard of the module docstring."""
    return fl.Layout(content=fl.TabContainer(selected_tab_index=0, tabs=[
        fl.TabItem(title="Rollover", content=_rollover_tab()), fl.TabItem(title="Speeds", content=_speeds_tab()),
        fl.TabItem(title="Innovations", content=_innovations_tab()),
        fl.TabItem(title="Parameters", content=_parameters_tab()), fl.TabItem(title="Map / 3D", content=_map_tab())]))


def layout_json() -> str:
    """The layout file's text: the SDK's JSON, indented for review, with a final newline."""
    import json

    return json.dumps(json.loads(build_layout().to_json()), indent=1) + "\n"


_PATH = re.compile(r"^(/[A-Za-z0-9_/.-]*?)\.((?:values|sigmas|fields)\.[A-Za-z0-9_]+)$")


def plotted_paths(layout_doc: dict) -> list[tuple[str, str]]:
    """(topic, field path) of every plot series and indicator in a layout document (the JSON of
    :func:`layout_json` loaded), e.g. ``("/est/state", "values.phi_v_rad")``."""
    out: list[tuple[str, str]] = []

    def walk(node):
        if isinstance(node, dict):
            for key in ("value", "path"):
                v = node.get(key)
                if isinstance(v, str) and v.startswith("/"):
                    m = _PATH.match(v)
                    out.append((m.group(1), m.group(2)) if m else (v, ""))
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(layout_doc)
    return out
