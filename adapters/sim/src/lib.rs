//! Built-in 2.5D simulator: worlds, UGV/UAV/sensor/radio models, lockstep runs.
