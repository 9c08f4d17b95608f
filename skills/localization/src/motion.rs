//! The odometry motion model (Thrun, Burgard & Fox, "Probabilistic Robotics", §5.4): the
//! relative motion between two odometry poses is decomposed into a first rotation, a
//! translation and a second rotation, and each is perturbed with noise whose standard deviation
//! grows with the rotations and the distance.

use rand::Rng;
use rand_distr::StandardNormal;
use spomp_core::{Pose2, normalize_angle};

use crate::params::LocalizationParams;

/// A relative motion as rotation–translation–rotation, with the noise of each part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct OdometryMotion {
    rot1: f64,
    trans: f64,
    rot2: f64,
    sigma_rot1: f64,
    sigma_trans: f64,
    sigma_rot2: f64,
}

/// The odometry noise coefficients of [`LocalizationParams`] (Thrun's α₁…α₄), all the motion
/// model needs: small enough to copy wherever odometry is composed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MotionNoise {
    rot_per_rad: f64,
    rot_per_m: f64,
    trans_per_m: f64,
    trans_per_rad: f64,
}

impl From<&LocalizationParams> for MotionNoise {
    fn from(params: &LocalizationParams) -> Self {
        MotionNoise {
            rot_per_rad: params.rot_noise_rad_per_rad,
            rot_per_m: params.rot_noise_rad_per_m,
            trans_per_m: params.trans_noise_m_per_m,
            trans_per_rad: params.trans_noise_m_per_rad,
        }
    }
}

/// Below this distance the direction of travel is undefined: all rotation goes to `rot2`.
const MIN_TRANSLATION_M: f64 = 1e-6;

impl OdometryMotion {
    /// Decomposes an odometry delta (the new pose in the old pose's frame).
    pub fn new(delta: Pose2, noise: MotionNoise) -> Self {
        let mut trans = delta.x.hypot(delta.y);
        let mut rot1 = if trans < MIN_TRANSLATION_M { 0.0 } else { delta.y.atan2(delta.x) };
        // Driving backwards is a translation of negative length, not a half turn each way.
        if rot1.abs() > std::f64::consts::FRAC_PI_2 {
            rot1 = normalize_angle(rot1 - std::f64::consts::PI);
            trans = -trans;
        }
        let rot2 = normalize_angle(delta.yaw - rot1);
        let (a1, a2, a3, a4) = (noise.rot_per_rad, noise.rot_per_m, noise.trans_per_m, noise.trans_per_rad);
        OdometryMotion {
            rot1,
            trans,
            rot2,
            sigma_rot1: (a1 * rot1).hypot(a2 * trans),
            sigma_trans: (a3 * trans).hypot(a4 * (rot1.abs() + rot2.abs())),
            sigma_rot2: (a1 * rot2).hypot(a2 * trans),
        }
    }

    /// Standard deviations of (along-track position, heading) that this motion adds.
    pub fn spread(&self) -> (f64, f64) {
        (self.sigma_trans, self.sigma_rot1.hypot(self.sigma_rot2))
    }

    /// Whether the motion is exactly zero (nothing to sample).
    pub fn is_still(&self) -> bool {
        self.rot1 == 0.0 && self.trans == 0.0 && self.rot2 == 0.0
    }

    /// Moves a pose by one noisy sample of the motion.
    #[inline]
    pub fn sample<R: Rng + ?Sized>(&self, pose: Pose2, rng: &mut R) -> Pose2 {
        let n1: f64 = rng.sample(StandardNormal);
        let n2: f64 = rng.sample(StandardNormal);
        let n3: f64 = rng.sample(StandardNormal);
        let rot1 = self.rot1 + self.sigma_rot1 * n1;
        let trans = self.trans + self.sigma_trans * n2;
        let rot2 = self.rot2 + self.sigma_rot2 * n3;
        let heading = pose.yaw + rot1;
        Pose2::new(pose.x + trans * heading.cos(), pose.y + trans * heading.sin(), normalize_angle(heading + rot2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn noiseless() -> LocalizationParams {
        LocalizationParams {
            rot_noise_rad_per_rad: 0.0,
            rot_noise_rad_per_m: 0.0,
            trans_noise_m_per_m: 0.0,
            trans_noise_m_per_rad: 0.0,
            ..Default::default()
        }
    }

    #[test]
    fn without_noise_the_sample_is_the_composition() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let start = Pose2::new(3.0, -2.0, 2.5);
        for delta in [
            Pose2::new(1.0, 0.2, 0.1),
            Pose2::new(-0.8, 0.1, -0.05),
            Pose2::new(0.0, 0.0, 1.0),
            Pose2::new(0.0, -1.0, 0.3),
        ] {
            let m = OdometryMotion::new(delta, (&noiseless()).into());
            let got = m.sample(start, &mut rng);
            let want = start.compose(delta);
            assert!((got.x - want.x).abs() < 1e-12 && (got.y - want.y).abs() < 1e-12, "{delta:?}");
            assert!(normalize_angle(got.yaw - want.yaw).abs() < 1e-12);
        }
    }

    #[test]
    fn noise_is_centred_and_grows_with_distance() {
        let params = LocalizationParams::default();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let delta = Pose2::new(2.0, 0.0, 0.0);
        let m = OdometryMotion::new(delta, (&params).into());
        let n = 20_000;
        let samples: Vec<Pose2> = (0..n).map(|_| m.sample(Pose2::default(), &mut rng)).collect();
        let mean_x = samples.iter().map(|p| p.x).sum::<f64>() / n as f64;
        let std_x = (samples.iter().map(|p| (p.x - mean_x).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!((mean_x - 2.0).abs() < 0.01, "{mean_x}");
        // σ_trans = 0.05 · 2 m = 0.1 m.
        assert!((std_x - 0.1).abs() < 0.01, "{std_x}");
        let (s_trans, s_rot) = m.spread();
        assert!((s_trans - 0.1).abs() < 1e-12);
        assert!((s_rot - (0.02f64).hypot(0.02)).abs() < 1e-12);
        assert!(OdometryMotion::new(Pose2::default(), (&params).into()).is_still());
    }
}
