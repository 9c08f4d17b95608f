//! Cross-view semantic localizer: a particle filter that localises a ground robot in the aerial
//! semantic map (SPOMP §"Cross-View Localizer", after Miller et al., "Any way you look at it"
//! and "Stronger together").
//!
//! * State: particles over (x, y, yaw) in the aerial map frame ([`CrossViewLocalizer`]).
//! * Motion: the odometry delta between panoramas, with noise proportional to the motion
//!   ([`CrossViewLocalizer::predict`]).
//! * Measurement: each semantic panorama is projected top-down into a sparse local grid at the
//!   map's resolution; each particle is scored by the class-wise distance of those cells to the
//!   aerial map under its pose ([`CrossViewLocalizer::update`]). Unknown aerial cells cost the
//!   same for every particle, so with no map the filter follows odometry.
//! * Resampling: systematic, when the effective sample size is low. Global re-localisation:
//!   augmented MCL, injecting the best of many random poses over known ground cells when the
//!   short-term likelihood falls below the long-term one.
//! * Output: [`spomp_core::PoseEstimate`] at panorama time, and at control rate by composing
//!   odometry since the last panorama ([`CrossViewLocalizer::pose_at`]).
//!
//! Pure library: no threads, no clock, no I/O; randomness comes from the caller's RNG.

mod error;
mod field;
mod filter;
mod motion;
mod observation;
mod params;
mod scoring;

pub use error::LocalizationError;
pub use field::MAX_WEIGHTED_CLASSES;
pub use filter::{CrossViewLocalizer, OdometryComposer, Particle, UpdateReport};
pub use params::{LocalizationParams, PosePrior};
