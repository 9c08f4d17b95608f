//! Every call the simulator makes on a robot's seam, for observers that record them: the robot
//! layer's own description of the seam's calls, which every adapter reports alike.

pub use spomp_robot::seam::{SeamInput, tier_bits};
