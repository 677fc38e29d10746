//! Ray intersection of the renderer's primitives: round cones (berries),
//! capsules (stems), masked flat patches (leaflets, sepals) and boxes (tray).
//! Every intersection returns the nearest hit in front of the ray origin
//! with an outward unit normal and shape-local coordinates for texturing.

use nalgebra::{Point3, Vector3};

/// A ray hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the (unit) ray.
    pub t: f64,
    /// Outward unit normal (facing the ray for patches).
    pub normal: Vector3<f64>,
    /// Shape-local coordinates for texturing (meaning depends on the shape).
    pub local: [f64; 2],
}

/// Outline of a flat patch in its normalised `(a, b)` coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatchShape {
    /// Serrated ellipse (strawberry leaflet).
    Leaflet,
    /// Narrow pointed sepal, base at `a = -1`.
    Sepal,
}

impl PatchShape {
    /// Whether `(a, b)` is inside the outline.
    pub fn contains(self, a: f64, b: f64) -> bool {
        match self {
            PatchShape::Leaflet => {
                let rho = (a * a + b * b).sqrt();
                if rho >= 1.0 {
                    return false;
                }
                let theta = b.atan2(a);
                let tooth = (theta * 15.0 / std::f64::consts::PI).rem_euclid(1.0);
                let serration = 0.09 * tooth * (rho * 2.0).min(1.0);
                rho < 1.0 - serration && !(a < -0.93)
            }
            PatchShape::Sepal => {
                if !(-1.0..=1.0).contains(&a) {
                    return false;
                }
                let s = 0.5 * (a + 1.0);
                b.abs() < (1.0 - s).powf(0.8) * (0.4 + 2.4 * s).min(1.0)
            }
        }
    }
}

/// A renderable primitive.
#[derive(Clone, Debug)]
pub enum Shape {
    /// Convex hull of two spheres (`r1` at `a`, `r2` at `b`).
    RoundCone {
        /// Shoulder centre.
        a: Point3<f64>,
        /// Tip centre.
        b: Point3<f64>,
        /// Shoulder radius.
        r1: f64,
        /// Tip radius.
        r2: f64,
        /// Unit vector perpendicular to the axis (texture azimuth origin).
        ref_dir: Vector3<f64>,
    },
    /// Capsule `a`-`b` of radius `r`.
    Capsule {
        /// One end.
        a: Point3<f64>,
        /// Other end.
        b: Point3<f64>,
        /// Radius.
        r: f64,
    },
    /// Flat patch centred at `c` spanning `u * hu` and `v * hv`.
    Patch {
        /// Centre.
        c: Point3<f64>,
        /// Unit in-plane direction (length).
        u: Vector3<f64>,
        /// Unit in-plane direction (width).
        v: Vector3<f64>,
        /// Half length.
        hu: f64,
        /// Half width.
        hv: f64,
        /// Outline.
        shape: PatchShape,
    },
    /// Axis-aligned box.
    Cuboid {
        /// Centre.
        c: Point3<f64>,
        /// Half extents.
        h: Vector3<f64>,
    },
}

impl Shape {
    /// Centre and radius of a sphere containing the shape.
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        match self {
            Shape::RoundCone { a, b, r1, r2, .. } => {
                let c = Point3::from((a.coords + b.coords) * 0.5);
                (c, 0.5 * (b - a).norm() + r1.max(*r2))
            }
            Shape::Capsule { a, b, r } => (
                Point3::from((a.coords + b.coords) * 0.5),
                0.5 * (b - a).norm() + r,
            ),
            Shape::Patch { c, hu, hv, .. } => (*c, (hu * hu + hv * hv).sqrt()),
            Shape::Cuboid { c, h } => (*c, h.norm()),
        }
    }

    /// Nearest hit of the ray `o + t d` (`d` unit) with `t > 0`.
    pub fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<Hit> {
        match self {
            Shape::RoundCone {
                a,
                b,
                r1,
                r2,
                ref_dir,
            } => round_cone_hit(o, d, a, b, *r1, *r2, ref_dir, self.bounding_sphere()),
            Shape::Capsule { a, b, r } => capsule_hit(o, d, a, b, *r),
            Shape::Patch {
                c,
                u,
                v,
                hu,
                hv,
                shape,
            } => patch_hit(o, d, c, u, v, *hu, *hv, *shape),
            Shape::Cuboid { c, h } => cuboid_hit(o, d, c, h),
        }
    }
}

/// Entry and exit of a ray through a sphere.
pub fn sphere_span(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    c: &Point3<f64>,
    r: f64,
) -> Option<(f64, f64)> {
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.norm_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some((-b - s, -b + s))
}

/// Exact signed distance to a round cone (Inigo Quilez's formulation).
pub fn round_cone_sdf(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, r1: f64, r2: f64) -> f64 {
    let ba = b - a;
    let l2 = ba.norm_squared();
    let rr = r1 - r2;
    let a2 = l2 - rr * rr;
    let il2 = 1.0 / l2;
    let pa = p - a;
    let y = pa.dot(&ba);
    let z = y - l2;
    let x2 = (pa * l2 - ba * y).norm_squared();
    let y2 = y * y * l2;
    let z2 = z * z * l2;
    let k = rr.signum() * rr * rr * x2;
    if z.signum() * a2 * z2 > k {
        return (x2 + z2).sqrt() * il2 - r2;
    }
    if y.signum() * a2 * y2 < k {
        return (x2 + y2).sqrt() * il2 - r1;
    }
    ((x2 * a2 * il2).sqrt() + y * rr) * il2 - r1
}

#[allow(clippy::too_many_arguments)]
fn round_cone_hit(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    r1: f64,
    r2: f64,
    ref_dir: &Vector3<f64>,
    (bc, br): (Point3<f64>, f64),
) -> Option<Hit> {
    let (t0, t1) = sphere_span(o, d, &bc, br)?;
    if t1 <= 0.0 {
        return None;
    }
    let eps = 1e-6 * r1.max(1e-3);
    let mut t = t0.max(0.0);
    for _ in 0..96 {
        let p = o + d * t;
        let dist = round_cone_sdf(&p, a, b, r1, r2);
        if dist < eps {
            let normal = sdf_normal(&p, a, b, r1, r2);
            let axis = (b - a).normalize();
            let rel = p - a;
            let s = rel.dot(&axis);
            let radial = rel - axis * s;
            let phi = radial.dot(&axis.cross(ref_dir)).atan2(radial.dot(ref_dir));
            return Some(Hit {
                t,
                normal,
                local: [s, phi],
            });
        }
        t += dist;
        if t > t1 {
            return None;
        }
    }
    None
}

fn sdf_normal(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>, r1: f64, r2: f64) -> Vector3<f64> {
    let h = 1e-6;
    let g = Vector3::from_fn(|i, _| {
        let mut e = Vector3::zeros();
        e[i] = h;
        round_cone_sdf(&(p + e), a, b, r1, r2) - round_cone_sdf(&(p - e), a, b, r1, r2)
    });
    g.try_normalize(1e-18).unwrap_or_else(Vector3::z)
}

fn capsule_hit(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    r: f64,
) -> Option<Hit> {
    // Inigo Quilez's ray-capsule intersection.
    let ba = b - a;
    let oa = o - a;
    let baba = ba.norm_squared();
    let bard = ba.dot(d);
    let baoa = ba.dot(&oa);
    let rdoa = d.dot(&oa);
    let oaoa = oa.norm_squared();
    let qa = baba - bard * bard;
    let qb = baba * rdoa - baoa * bard;
    let qc = baba * oaoa - baoa * baoa - r * r * baba;
    let h = qb * qb - qa * qc;
    if h >= 0.0 && qa > 1e-18 {
        let t = (-qb - h.sqrt()) / qa;
        let y = baoa + t * bard;
        if y > 0.0 && y < baba && t > 0.0 {
            let p = o + d * t;
            let axis_pt = a + ba * (y / baba);
            return Some(Hit {
                t,
                normal: (p - axis_pt) / r,
                local: [y / baba, 0.0],
            });
        }
    }
    // Caps.
    let cap = |c: &Point3<f64>, s: f64| {
        sphere_span(o, d, c, r).and_then(|(t0, _)| {
            (t0 > 0.0).then(|| Hit {
                t: t0,
                normal: (o + d * t0 - c) / r,
                local: [s, 0.0],
            })
        })
    };
    match (cap(a, 0.0), cap(b, 1.0)) {
        (Some(x), Some(y)) => Some(if x.t < y.t { x } else { y }),
        (x, y) => x.or(y),
    }
}

#[allow(clippy::too_many_arguments)]
fn patch_hit(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    c: &Point3<f64>,
    u: &Vector3<f64>,
    v: &Vector3<f64>,
    hu: f64,
    hv: f64,
    shape: PatchShape,
) -> Option<Hit> {
    let n = u.cross(v);
    let denom = n.dot(d);
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = (c - o).dot(&n) / denom;
    if t <= 0.0 {
        return None;
    }
    let rel = o + d * t - c;
    let (a, b) = (rel.dot(u) / hu, rel.dot(v) / hv);
    shape.contains(a, b).then(|| Hit {
        t,
        normal: if denom > 0.0 { -n } else { n },
        local: [a, b],
    })
}

fn cuboid_hit(o: &Point3<f64>, d: &Vector3<f64>, c: &Point3<f64>, h: &Vector3<f64>) -> Option<Hit> {
    let (mut tmin, mut tmax, mut axis) = (f64::NEG_INFINITY, f64::INFINITY, 0);
    for i in 0..3 {
        let oi = o[i] - c[i];
        if d[i].abs() < 1e-15 {
            if oi.abs() > h[i] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((-h[i] - oi) / d[i], (h[i] - oi) / d[i]);
        let (t0, t1) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
        if t0 > tmin {
            tmin = t0;
            axis = i;
        }
        tmax = tmax.min(t1);
    }
    if tmin > tmax || tmin <= 0.0 {
        return None;
    }
    let mut normal = Vector3::zeros();
    normal[axis] = -d[axis].signum();
    let p = o + d * tmin - c;
    let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
    Some(Hit {
        t: tmin,
        normal,
        local: [p[i], p[j]],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray_to(o: Point3<f64>, target: Point3<f64>) -> Vector3<f64> {
        (target - o).normalize()
    }

    #[test]
    fn round_cone_sdf_matches_spheres_at_the_ends() {
        let (a, b) = (Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 0.0, -0.02));
        // Above the shoulder: distance to the big sphere.
        let p = Point3::new(0.0, 0.0, 0.05);
        assert!((round_cone_sdf(&p, &a, &b, 0.015, 0.006) - (0.05 - 0.015)).abs() < 1e-12);
        // Below the tip: distance to the small sphere.
        let p = Point3::new(0.0, 0.0, -0.1);
        assert!((round_cone_sdf(&p, &a, &b, 0.015, 0.006) - (0.08 - 0.006)).abs() < 1e-12);
    }

    #[test]
    fn ray_hits_agree_with_closed_forms() {
        let o = Point3::new(-1.0, 0.0, 0.0);
        let d = Vector3::x();
        // Capsule side: hit at x = -r.
        let cap = Shape::Capsule {
            a: Point3::new(0.0, 0.0, -0.1),
            b: Point3::new(0.0, 0.0, 0.1),
            r: 0.01,
        };
        let h = cap.intersect(&o, &d).unwrap();
        assert!((h.t - 0.99).abs() < 1e-12 && (h.normal + Vector3::x()).norm() < 1e-9);
        // Round cone seen side-on at the shoulder: hit at x = -r1.
        let rc = Shape::RoundCone {
            a: Point3::origin(),
            b: Point3::new(0.0, 0.0, -0.02),
            r1: 0.015,
            r2: 0.006,
            ref_dir: Vector3::x(),
        };
        let h = rc.intersect(&o, &d).unwrap();
        assert!((h.t - 0.985).abs() < 1e-5, "{}", h.t);
        // Box face.
        let bx = Shape::Cuboid {
            c: Point3::new(0.5, 0.0, 0.0),
            h: Vector3::new(0.1, 0.2, 0.3),
        };
        let h = bx.intersect(&o, &d).unwrap();
        assert!((h.t - 1.4).abs() < 1e-12 && h.normal == -Vector3::x());
        // A patch facing the ray.
        let p = Shape::Patch {
            c: Point3::new(0.2, 0.0, 0.0),
            u: Vector3::y(),
            v: Vector3::z(),
            hu: 0.02,
            hv: 0.01,
            shape: PatchShape::Leaflet,
        };
        let h = p.intersect(&o, &d).unwrap();
        assert!((h.t - 1.2).abs() < 1e-12 && h.normal.dot(&d) < 0.0);
    }

    #[test]
    fn misses_miss() {
        let o = Point3::new(-1.0, 0.5, 0.0);
        let target = Point3::new(0.0, 0.5, 0.0);
        let rc = Shape::RoundCone {
            a: Point3::origin(),
            b: Point3::new(0.0, 0.0, -0.02),
            r1: 0.015,
            r2: 0.006,
            ref_dir: Vector3::x(),
        };
        assert!(rc.intersect(&o, &ray_to(o, target)).is_none());
        // Behind the origin.
        assert!(rc
            .intersect(&Point3::new(1.0, 0.0, 0.0), &Vector3::x())
            .is_none());
    }

    #[test]
    fn sepal_and_leaflet_outlines() {
        assert!(PatchShape::Leaflet.contains(0.0, 0.0));
        assert!(!PatchShape::Leaflet.contains(0.99, 0.1));
        assert!(PatchShape::Sepal.contains(-0.5, 0.0));
        assert!(!PatchShape::Sepal.contains(0.999, 0.2));
    }
}
