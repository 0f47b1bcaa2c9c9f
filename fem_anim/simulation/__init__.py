"""The time loop (seed section 3.1): the simulation of a scene and its step (``loop``), the
integrators' predictors and updates (``integrators``), the initial state (``initial_state``),
each step's start (``newton_start``), adaptive retries (``adaptive``), the frame loop and its
files (``run_loop``), checkpoints and resume (one body's and, ``joint_checkpoint``, a shell
beside solids'), interrupts, the progress bar, the handles'
work per step (``handle_work``) and the energy report.
"""

from fem_anim.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "Checkpoint": "checkpoint",
    "load_checkpoint": "checkpoint",
    "save_checkpoint": "checkpoint",
    "scene_hash": "checkpoint",
    "load_joint_checkpoint": "joint_checkpoint",
    "save_joint_checkpoint": "joint_checkpoint",
    "AT_REST": "energy_report",
    "DAMPED_THRESHOLD": "energy_report",
    "ROUNDOFF_STRAIN": "energy_report",
    "describe_energy": "energy_report",
    "energy_report": "energy_report",
    "initial_energies": "energy_report",
    "moving_pins": "energy_report",
    "roundoff_energy": "energy_report",
    "write_summary": "energy_report",
    "handle_work": "handle_work",
    "center_of_mass": "initial_state",
    "initial_velocity": "initial_state",
    "rigid_velocity": "initial_state",
    "Integrator": "integrators",
    "State": "integrators",
    "Interrupts": "interrupt",
    "SIGNALS": "interrupt",
    "stop_at_once": "interrupt",
    "GRACE_S": "signal_watch",
    "AdaptiveStepper": "adaptive",
    "FrameClock": "frame_clock",
    "frame_clock": "frame_clock",
    "RunResult": "run_loop",
    "Simulation": "loop",
    "JointSimulation": "joint_loop",
    "split_joint_scene": "joint_loop",
    "solver_options": "loop",
    "collision_free_guess": "newton_start",
    "initial_guess": "newton_start",
    "Progress": "progress",
})
