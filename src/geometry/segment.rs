//! Closest points and distances between segments in `f64` (points are
//! segments of zero length): the kernel of the capsule, hull and
//! broad-phase distances of the robot and the scene.

use nalgebra::Vector3;

/// Closest points between segments `p1`–`q1` and `p2`–`q2` (Ericson,
/// "Real-Time Collision Detection" §5.1.9).
#[inline]
pub fn closest_segments(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    const EPS: f64 = 1e-18;
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(&r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            let mut s = if denom > EPS {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p1 + d1 * s, p2 + d2 * t)
}

/// Distance between the segments `p1`–`q1` and `p2`–`q2` (closest points
/// from [`closest_segments`]); points are segments of zero length.
#[inline]
pub fn segment_distance(
    p1: &Vector3<f64>,
    q1: &Vector3<f64>,
    p2: &Vector3<f64>,
    q2: &Vector3<f64>,
) -> f64 {
    let (x, y) = closest_segments(p1, q1, p2, q2);
    (x - y).norm()
}

/// Distance from `p` to the segment `a`–`b`.
#[inline]
pub fn point_segment_distance(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let (_, y) = closest_segments(p, p, a, b);
    (y - p).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_segments_handles_parallel_and_crossing() {
        let z = Vector3::zeros;
        let (x, y) = closest_segments(
            &z(),
            &Vector3::x(),
            &Vector3::new(0.5, 1.0, -1.0),
            &Vector3::new(0.5, 1.0, 1.0),
        );
        assert!(
            (x - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-12
                && (y - Vector3::new(0.5, 1.0, 0.0)).norm() < 1e-12
        );
        let (x, y) = closest_segments(
            &z(),
            &Vector3::x(),
            &Vector3::new(0.0, 1.0, 0.0),
            &Vector3::new(1.0, 1.0, 0.0),
        );
        assert!(((x - y).norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn segment_distance_matches_dense_sampling() {
        let cases = [
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.5, 1.0, -1.0],
                [0.5, 1.0, 1.0],
                1.0,
            ),
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [3.0, 1.0, 0.0],
                1.0,
            ),
            (
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 0.5, 0.0],
                [1.0, 0.5, 0.0],
                0.5,
            ),
            (
                [0.2, 0.3, 0.1],
                [0.2, 0.3, 0.1],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                0.36055512754639896,
            ),
        ];
        for (p1, q1, p2, q2, expect) in cases {
            let (p1, q1, p2, q2) = (
                Vector3::from(p1),
                Vector3::from(q1),
                Vector3::from(p2),
                Vector3::from(q2),
            );
            let d = segment_distance(&p1, &q1, &p2, &q2);
            assert!((d - expect).abs() < 1e-12, "{d} vs {expect}");
            let mut brute = f64::INFINITY;
            for i in 0..=200 {
                for j in 0..=200 {
                    let x = p1 + (q1 - p1) * (i as f64 / 200.0);
                    let y = p2 + (q2 - p2) * (j as f64 / 200.0);
                    brute = brute.min((x - y).norm());
                }
            }
            assert!(d <= brute + 1e-12 && brute - d < 1e-2, "{d} vs {brute}");
        }
    }
}
