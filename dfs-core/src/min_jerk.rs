//! The minimum-jerk profile of a point-to-point move (Flash & Hogan 1985), the one formula the
//! simulated operator, the replay and the segmentation share:
//! `s(τ) = 10τ³ − 15τ⁴ + 6τ⁵` on `τ ∈ [0, 1]`, the fraction of the displacement covered at the
//! fraction `τ` of the move's duration.

use crate::math::Real;

/// The fraction of the displacement covered at `tau` (the fraction of the duration), `tau`
/// clamped to [0, 1]: 0 at the start, 1 at the end, ½ halfway.
pub fn progress(tau: Real) -> Real {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

/// The first derivative `ds/dτ` of [`progress`] at `tau`, `tau` clamped to [0, 1] (0 at both
/// ends, 1.875 halfway; multiply by `1 / duration` for a rate per second).
pub fn velocity(tau: Real) -> Real {
    let t = tau.clamp(0.0, 1.0);
    let u = t * (1.0 - t);
    30.0 * u * u
}

/// The second derivative `d²s/dτ²` of [`progress`] at `tau`, `tau` clamped to [0, 1] (0 at
/// both ends; multiply by `1 / duration²` for an acceleration per second squared).
pub fn acceleration(tau: Real) -> Real {
    let t = tau.clamp(0.0, 1.0);
    let (t2, t3) = (t * t, t * t * t);
    60.0 * t - 180.0 * t2 + 120.0 * t3
}

/// The `tau` at which the profile has covered the fraction `s` of its displacement (the
/// inverse of [`progress`]), `s` clamped to [0, 1]; found by bisection to about 1e-16. A NaN
/// `s` gives (about) 0.
pub fn time_at_progress(s: Real) -> Real {
    let s = s.clamp(0.0, 1.0);
    if s > 0.5 {
        // The profile is point-symmetric about (½, ½).
        return 1.0 - time_at_progress(1.0 - s);
    }
    let (mut lo, mut hi) = (0.0, 0.5);
    for _ in 0..60 {
        let t = 0.5 * (lo + hi);
        if progress(t) < s {
            lo = t;
        } else {
            hi = t;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_profile_runs_from_rest_to_rest_and_is_symmetric() {
        assert_eq!(progress(0.0), 0.0);
        assert_eq!(progress(1.0), 1.0);
        assert_eq!(progress(-1.0), 0.0);
        assert_eq!(progress(2.0), 1.0);
        assert!((progress(0.5) - 0.5).abs() < 1e-15);
        assert_eq!(acceleration(0.0), 0.0);
        assert_eq!((velocity(0.0), velocity(1.0)), (0.0, 0.0));
        assert!((velocity(0.5) - 1.875).abs() < 1e-15);
        assert!(acceleration(1.0).abs() < 1e-12);
        for k in 0..=20 {
            let t = k as Real / 20.0;
            assert!((progress(t) + progress(1.0 - t) - 1.0).abs() < 1e-12, "{t}");
            // The velocity and acceleration are the first and second differences of the
            // progress.
            let h = 1e-4;
            if (h..=1.0 - h).contains(&t) {
                let first = (progress(t + h) - progress(t - h)) / (2.0 * h);
                assert!((first - velocity(t)).abs() < 1e-6, "{t}");
                let second = (progress(t + h) - 2.0 * progress(t) + progress(t - h)) / (h * h);
                assert!((second - acceleration(t)).abs() < 1e-4, "{t}");
            }
        }
    }

    #[test]
    fn ten_to_ninety_percent_of_a_minimum_jerk_move_is_about_half_its_duration() {
        let t10 = time_at_progress(0.1);
        let t90 = time_at_progress(0.9);
        assert!((t90 - t10 - 0.507).abs() < 0.01, "{t10} {t90}");
        assert!((t10 + t90 - 1.0).abs() < 1e-12);
        for s in [0.0, 0.1, 0.25, 0.5, 0.75, 1.0] {
            assert!((progress(time_at_progress(s)) - s).abs() < 1e-12, "{s}");
        }
        assert!(time_at_progress(Real::NAN) < 1e-15);
    }
}
