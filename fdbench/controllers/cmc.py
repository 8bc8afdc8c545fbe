"""Computed muscle control (``--controller cmc``) of a model with muscles: the muscles' excitations
and the reserve torques (the model's actuators, else one per coordinate), found window by window
(``fdbench.multibody.cmc``)."""

from __future__ import annotations

import numpy as np

from ..method_options import MethodOption
from ..multibody import cmc
from .base import (CONTROLLERS, Controller, Design, Plan, check_non_negative, check_positive,
                   muscle_columns, per_joint)

# A compliant tendon's explicit form is stiff where its muscle is barely active (fdbench's arm26: RK4
# at 1e-4 s fails within 0.9 s of its default motion under CMC, at 5e-5 s it runs): with compliant
# tendons CMC steps at most this (s) whatever --dt, and says so in its record (``cmc_step_s``).
COMPLIANT_MAX_STEP = 5e-5
TENDONS = ("model", "rigid")  # the muscles' tendons: the model's, or every compliant one taken as rigid


@CONTROLLERS.register("cmc")
class CMC(Controller):
    """Computed muscle control as OpenSim's CMC (Thelen and Anderson 2006): per control window of
    ``window`` s, desired accelerations from the motion at the window's end with task gains ``kp``
    (1/s^2) and ``kd`` (1/s) (OpenSim's CMC examples' 100 and 20: critically damped at 10 rad/s),
    static optimisation of the muscles' activations and reserve torques (the model's actuators, each
    of its optimal force or ``reserve_optimal_force`` N m per unit control; a model without
    actuators: one per coordinate, default 1) for the inverse-dynamics forces, then the excitations
    that give those muscle forces at the window's end; see ``fdbench.multibody.cmc``."""

    name = "cmc"
    summary = ("computed muscle control of a model with muscles (Thelen and Anderson; OpenSim's CMCTool): per "
               "window, static optimisation of the muscles and reserves for PD-corrected accelerations, then "
               "the excitations that reach those forces")

    command_line = {
        "window": MethodOption("control window (look-ahead) T, s; OpenSim's CMC default 0.01.", default=None,
                               show_default=False),
        "reserve_optimal_force": MethodOption("optimal force of every reserve, N m per unit control (default: "
                                              "each of the model's [[actuators]] its own; without actuators 1 per "
                                              "coordinate). A coordinate without an actuator has no reserve: the "
                                              "torque its muscles miss is reported unmet.", show_default=False),
        "tendons": MethodOption("the muscles' tendons: model (as the model has them) or rigid (every compliant "
                                "tendon taken as rigid, as collocate --actuation muscles and Moco's "
                                "ModOpIgnoreTendonCompliance take them: CMC then steps at --dt).", type=str,
                                default=None, show_default=False, metavar="model|rigid"),
    }

    def __init__(self, kp: float = cmc.DEFAULT_KP, kd: float = cmc.DEFAULT_KD, window: float = cmc.DEFAULT_WINDOW,
                 reserve_optimal_force: float | None = None, tendons: str = "model"):
        self.kp = check_non_negative("--kp", kp)  # 1/s^2
        self.kd = check_non_negative("--kd", kd)  # 1/s
        self.window = check_positive("--window", window)  # s
        self.reserve_optimal_force = (None if reserve_optimal_force is None  # N m; None: the model's actuators
                                      else check_positive("--reserve-optimal-force", reserve_optimal_force))
        if tendons not in TENDONS:
            raise ValueError(f"--tendons must be one of {', '.join(TENDONS)}, got {tendons!r}")
        self.tendons = tendons

    def check_model(self, model) -> None:
        if not model.muscles:
            raise ValueError(f"--controller cmc: model {model.name!r} has no muscles ([[muscles]] in its file); "
                             "use pd, computed-torque or lqr")

    def check_run(self, model, duration: float, dt: float) -> None:
        cmc.check_window(self.window, duration, self.step(model, dt))

    def step(self, model, dt: float) -> float:
        """The RK4 step (s) CMC takes on ``model`` for a requested ``dt`` (s)."""
        compliant = self.tendons == "model" and any(m.tendon == "compliant" for m in model.muscles)
        return min(dt, COMPLIANT_MAX_STEP) if compliant else dt

    def warm_up(self, plan: Plan) -> None:
        cmc.warm_up(plan.engine.with_rigid_tendons() if self.tendons == "rigid" else plan.engine)

    def design(self, plan: Plan) -> Design:
        raise NotImplementedError("cmc simulates window by window: use CMC.run")

    def run(self, plan: Plan, plant, motion, grid, dt: float):
        """The CMC run of ``plant`` (an Engine) along ``motion``: (Simulation, record fields, extra
        trajectory columns (header, (n, k) values)). ``grid``: the motion's half steps for dt, used
        unless compliant tendons take a shorter step."""
        step, nominal = self.step(plan.model, dt), plan.engine
        taken = [m.name for m in plan.model.muscles if m.tendon == "compliant"] if self.tendons == "rigid" else []
        if taken:
            plant, nominal = plant.with_rigid_tendons(), nominal.with_rigid_tendons()
        done = cmc.computed_muscle_control(plant, motion, self.kp, self.kd, self.window, self.reserve_optimal_force,
                                           step, nominal=nominal, grid=grid if step == dt else None)
        result = done.simulation
        if not result.success and not taken and any(m.tendon == "compliant" for m in plan.model.muscles):
            result.detail = "; ".join(filter(None, [result.detail, "with the model's compliant tendons (--tendons "
                                                                   "rigid takes them as rigid)"]))
        per_reserve, rho = done.reserve_rms(), cmc.reserve_strengths(plan.model, self.reserve_optimal_force)
        muscles, joints = [m.name for m in plant.model.muscles], plan.joints
        reserved = rho > 0
        fields = {"reserve_rms_nm": float(np.sqrt(np.mean(per_reserve[reserved] ** 2))) if reserved.any() else 0.0,
                  **per_joint("reserve_rms_nm", joints, per_reserve),
                  "cmc_window_s": done.window, "cmc_kp": self.kp, "cmc_kd": self.kd,
                  "reserve_optimal_force": (float(rho[0]) if reserved.all() and np.all(rho == rho[0])
                                            else "per actuator (see reserves)"),
                  "cmc_step_s": step,
                  "tendons": f"rigid (compliant taken as rigid: {', '.join(taken)})" if taken else "model",
                  "cmc_windows": done.windows_done}
        if not reserved.all():  # the torque left unmet where a coordinate has no reserve
            per_unmet = done.unmet_rms()
            fields["unmet_rms_nm"] = float(np.sqrt(np.mean(per_unmet[~reserved] ** 2)))
            fields.update(per_joint("unmet_rms_nm", joints, np.where(reserved, 0.0, per_unmet)))
        header, values = muscle_columns(result, muscles)
        return result, fields, (header + [f"{j}_reserve" for j in joints],
                                np.column_stack([values, done.reserve_on_samples]))
