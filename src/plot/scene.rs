//! The sensed point cloud over the scene, in the robot base frame: a top
//! view (x right, y up) and a side view (x right, z up), side by side, each
//! at one metre scale on both axes (`dpmp data preview`, `dpmp plan --plot`
//! with `world: depth`).
//!
//! Obstacles are drawn as their projected outlines, filled translucent: a
//! sphere as its disc, a capsule (and a berry's body and stem) as the disc
//! swept along its projected axis, a cylinder, a box and a convex obstacle
//! as the convex hull of their projected rims, corners or points, and a
//! `points` obstacle as dots. Intruders (objects placed across the path
//! after the demonstrations) have a colour of their own. The sensed cloud
//! is drawn over them as dark blue dots, then the TCP path (red, a disc at
//! its start and a triangle at its end) and the target (a cross). Each
//! panel spans everything it draws plus [`MARGIN_M`], the shorter range
//! padded so that both axes keep the same scale.

use super::{format_of, plot_error, register_font, write_via_temp, Format};
use crate::geometry::quaternion::from_xyzw;
use crate::scene::{BerryShape, Obstacle, ObstacleShape};
use crate::Result;
use nalgebra::Vector3;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// Margin (m) around everything a panel draws.
pub const MARGIN_M: f64 = 0.05;

/// What [`scene_picture`] draws (all in the robot base frame, m).
#[derive(Clone, Debug)]
pub struct ScenePicture<'a> {
    /// Title above both panels.
    pub title: String,
    /// Legend label of the obstacles (e.g. `true scene`, `posted obstacles`).
    pub scene_label: String,
    /// The obstacles (request schema).
    pub obstacles: &'a [Obstacle],
    /// Per obstacle, whether it is an intruder (drawn in its own colour);
    /// missing entries count as `false`, so `&[]` marks none.
    pub intruder: &'a [bool],
    /// The sensed cloud's points.
    pub cloud: &'a [[f64; 3]],
    /// The TCP path, in order, when there is one.
    pub tcp_path: Option<&'a [[f64; 3]]>,
    /// The target (the berry centre), when there is one.
    pub target: Option<[f64; 3]>,
}

/// Draw `picture` into `path` (`.png` or `.svg`, by the extension): the top
/// and side views of the obstacles, the sensed cloud, the TCP path and the
/// target, with a legend. The file is written whole or not at all.
pub fn scene_picture(path: &Path, picture: &ScenePicture) -> Result<()> {
    register_font();
    let size = (1600, 860);
    let format = format_of(path, "out")?;
    write_via_temp(path, |tmp| match format {
        Format::Png => draw(BitMapBackend::new(tmp, size).into_drawing_area(), picture)
            .map_err(plot_error(path)),
        Format::Svg => {
            draw(SVGBackend::new(tmp, size).into_drawing_area(), picture).map_err(plot_error(path))
        }
    })
}

/// The obstacles' colour.
const SCENE: RGBColor = RGBColor(60, 150, 60);
/// The intruders' colour.
const INTRUDER: RGBColor = RGBColor(235, 120, 20);
/// The sensed cloud's colour.
const CLOUD: RGBColor = RGBColor(20, 40, 140);
/// The TCP path's colour.
const PATH: RGBColor = RGBColor(215, 30, 30);
/// The target's colour.
const TARGET: RGBColor = RGBColor(150, 0, 150);

/// Pixels around a panel's chart.
const CHART_MARGIN_PX: u32 = 12;
/// Height of a panel's x label area.
const X_LABEL_PX: u32 = 44;
/// Width of a panel's y label area.
const Y_LABEL_PX: u32 = 64;
/// Height of the legend strip.
const LEGEND_PX: u32 = 48;
/// Segments of a projected circle.
const CIRCLE_SEGMENTS: usize = 36;

/// A panel: which base axis is vertical.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum View {
    /// x horizontal, y vertical.
    Top,
    /// x horizontal, z vertical.
    Side,
}

impl View {
    fn vertical(self) -> usize {
        match self {
            View::Top => 1,
            View::Side => 2,
        }
    }

    fn project(self, p: &[f64; 3]) -> (f64, f64) {
        (p[0], p[self.vertical()])
    }

    fn caption(self) -> &'static str {
        match self {
            View::Top => "top view (x, y)",
            View::Side => "side view (x, z)",
        }
    }

    fn vertical_desc(self) -> &'static str {
        match self {
            View::Top => "y [m]",
            View::Side => "z [m]",
        }
    }
}

/// Everything one panel draws, projected onto its plane.
struct Projected {
    /// Obstacle outlines (convex polygons), each with its intruder mark.
    outlines: Vec<(Vec<(f64, f64)>, bool)>,
    /// The points of `points` obstacles, each with its intruder mark.
    dots: Vec<((f64, f64), bool)>,
    cloud: Vec<(f64, f64)>,
    path: Vec<(f64, f64)>,
    target: Option<(f64, f64)>,
}

fn finite(p: &(f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

impl Projected {
    fn new(picture: &ScenePicture, view: View) -> Projected {
        let mut outlines = Vec::new();
        let mut dots = Vec::new();
        for (i, obstacle) in picture.obstacles.iter().enumerate() {
            let intruder = picture.intruder.get(i).copied().unwrap_or(false);
            match &obstacle.shape {
                ObstacleShape::Points { points, .. } => dots.extend(
                    points
                        .iter()
                        .map(|p| view.project(p))
                        .filter(finite)
                        .map(|p| (p, intruder)),
                ),
                shape => outlines.extend(
                    outlines_of(shape, view)
                        .into_iter()
                        .filter(|o| !o.is_empty())
                        .map(|o| (o, intruder)),
                ),
            }
        }
        let project_all = |points: &[[f64; 3]]| -> Vec<(f64, f64)> {
            points
                .iter()
                .map(|p| view.project(p))
                .filter(finite)
                .collect()
        };
        Projected {
            outlines,
            dots,
            cloud: project_all(picture.cloud),
            path: picture.tcp_path.map(project_all).unwrap_or_default(),
            target: picture.target.map(|t| view.project(&t)).filter(finite),
        }
    }

    /// `[x_min, x_max, y_min, y_max]` of everything drawn (`None`: nothing).
    fn bounds(&self) -> Option<[f64; 4]> {
        let all = self
            .outlines
            .iter()
            .flat_map(|(o, _)| o.iter().copied())
            .chain(self.dots.iter().map(|(p, _)| *p))
            .chain(self.cloud.iter().copied())
            .chain(self.path.iter().copied())
            .chain(self.target);
        all.fold(None, |b: Option<[f64; 4]>, (x, y)| {
            Some(match b {
                None => [x, x, y, y],
                Some([x0, x1, y0, y1]) => [x0.min(x), x1.max(x), y0.min(y), y1.max(y)],
            })
        })
    }
}

/// The projected outlines of one (non-`points`) obstacle: convex polygons.
fn outlines_of(shape: &ObstacleShape, view: View) -> Vec<Vec<(f64, f64)>> {
    match shape {
        ObstacleShape::Sphere(s) => vec![stadium(view, &s.center, &s.center, s.radius)],
        ObstacleShape::Capsule(c) => vec![stadium(view, &c.a, &c.b, c.radius)],
        ObstacleShape::Cylinder { a, b, radius } => {
            vec![convex_hull(
                cylinder_rims(a, b, *radius).iter().map(|p| view.project(p)),
            )]
        }
        ObstacleShape::Box(b) => {
            let rotation = from_xyzw(&b.rotation);
            let c = Vector3::from(b.center);
            let h = b.half_extents;
            let corners = (0..8).map(|k| {
                let sign = |bit: usize| if k & (1 << bit) == 0 { -1.0 } else { 1.0 };
                let local = Vector3::new(sign(0) * h[0], sign(1) * h[1], sign(2) * h[2]);
                let p: [f64; 3] = (c + rotation * local).into();
                view.project(&p)
            });
            vec![convex_hull(corners)]
        }
        ObstacleShape::Convex { points } => {
            vec![convex_hull(points.iter().map(|p| view.project(p)))]
        }
        ObstacleShape::Berry(berry) => berry_outlines(berry, view),
        ObstacleShape::Points { .. } => Vec::new(),
    }
}

/// A berry's body (a ball, or a capsule along the stem axis when
/// elongated) and its stem, from the top of the body to `stem_top`, as the
/// obstacle code defines them.
fn berry_outlines(berry: &BerryShape, view: View) -> Vec<Vec<(f64, f64)>> {
    let c = Vector3::from(berry.center);
    let top = Vector3::from(berry.stem_top);
    let up = (top - c).try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let body_a: [f64; 3] = (c - up * berry.elongation).into();
    let body_b: [f64; 3] = (c + up * berry.elongation).into();
    let stem_base: [f64; 3] =
        (c + up * (berry.elongation + berry.radius - berry.stem_radius).max(0.0)).into();
    vec![
        stadium(view, &body_a, &body_b, berry.radius),
        stadium(view, &stem_base, &berry.stem_top, berry.stem_radius),
    ]
}

/// The projection of the capsule `a`–`b` of `radius` (a disc when `a` is
/// `b`): the hull of the discs at both projected ends.
fn stadium(view: View, a: &[f64; 3], b: &[f64; 3], radius: f64) -> Vec<(f64, f64)> {
    let ends = [view.project(a), view.project(b)];
    convex_hull(ends.into_iter().flat_map(|(x, y)| {
        (0..CIRCLE_SEGMENTS).map(move |k| {
            let t = std::f64::consts::TAU * k as f64 / CIRCLE_SEGMENTS as f64;
            (x + radius * t.cos(), y + radius * t.sin())
        })
    }))
}

/// Points on the rims of the end faces of the cylinder `a`–`b`.
fn cylinder_rims(a: &[f64; 3], b: &[f64; 3], radius: f64) -> Vec<[f64; 3]> {
    let (a, b) = (Vector3::from(*a), Vector3::from(*b));
    let axis = (b - a).try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let helper = if axis.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = axis.cross(&helper).normalize();
    let v = axis.cross(&u);
    (0..CIRCLE_SEGMENTS)
        .flat_map(|k| {
            let t = std::f64::consts::TAU * k as f64 / CIRCLE_SEGMENTS as f64;
            let offset = (u * t.cos() + v * t.sin()) * radius;
            let (on_a, on_b): ([f64; 3], [f64; 3]) = ((a + offset).into(), (b + offset).into());
            [on_a, on_b]
        })
        .collect()
}

/// The convex hull of `points` (Andrew's monotone chain), counter-clockwise;
/// non-finite points are dropped, fewer than three are returned as they are.
fn convex_hull(points: impl IntoIterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = points.into_iter().filter(finite).collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(2 * p.len());
    for pass in [p.clone(), p.iter().rev().copied().collect()] {
        let start = hull.len();
        for q in pass {
            while hull.len() >= start + 2 {
                let n = hull.len();
                if cross(hull[n - 2], hull[n - 1], q) > 0.0 {
                    break;
                }
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The axis ranges of a panel whose plotting area is `pixels` (w, h): the
/// bounds plus [`MARGIN_M`], the shorter range padded about its centre so
/// that a metre is as many pixels on both axes.
fn equal_scale_ranges(bounds: Option<[f64; 4]>, pixels: (u32, u32)) -> (Range<f64>, Range<f64>) {
    let [x0, x1, y0, y1] = bounds.unwrap_or([0.0, 0.0, 0.0, 0.0]);
    let (x0, x1, y0, y1) = (x0 - MARGIN_M, x1 + MARGIN_M, y0 - MARGIN_M, y1 + MARGIN_M);
    let (w, h) = (f64::from(pixels.0.max(1)), f64::from(pixels.1.max(1)));
    let metres_per_px = ((x1 - x0) / w).max((y1 - y0) / h);
    let (half_w, half_h) = (0.5 * metres_per_px * w, 0.5 * metres_per_px * h);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    (cx - half_w..cx + half_w, cy - half_h..cy + half_h)
}

/// What drawing on a `DB` area returns.
type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// The title, both panels and the legend.
fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    picture: &ScenePicture,
) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let root = root.titled(&picture.title, ("sans-serif", 24))?;
    let (_, height) = root.dim_in_pixel();
    let (body, legend) = root.split_vertically(height.saturating_sub(LEGEND_PX));
    let panels = body.split_evenly((1, 2));
    for (panel, view) in panels.iter().zip([View::Top, View::Side]) {
        draw_panel(panel, view, picture)?;
    }
    draw_legend(&legend, picture)?;
    root.present()?;
    Ok(())
}

/// One view: its caption, axes, obstacles, cloud, path and target.
fn draw_panel<DB: DrawingBackend>(
    panel: &DrawingArea<DB, Shift>,
    view: View,
    picture: &ScenePicture,
) -> DrawResult<DB> {
    let panel = panel.titled(view.caption(), ("sans-serif", 18))?;
    let (w, h) = panel.dim_in_pixel();
    let plot_px = (
        w.saturating_sub(2 * CHART_MARGIN_PX + Y_LABEL_PX),
        h.saturating_sub(2 * CHART_MARGIN_PX + X_LABEL_PX),
    );
    let projected = Projected::new(picture, view);
    let (xs, ys) = equal_scale_ranges(projected.bounds(), plot_px);
    let mut chart = ChartBuilder::on(&panel)
        .margin(CHART_MARGIN_PX)
        .x_label_area_size(X_LABEL_PX)
        .y_label_area_size(Y_LABEL_PX)
        .build_cartesian_2d(xs, ys)?;
    chart
        .configure_mesh()
        .x_desc("x [m]")
        .y_desc(view.vertical_desc())
        .x_label_formatter(&|v| format!("{v:.2}"))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .label_style(("sans-serif", 13))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let colour = |intruder: bool| if intruder { INTRUDER } else { SCENE };
    // Plant first, intruders over it.
    for layer in [false, true] {
        let outlines = projected.outlines.iter().filter(|(_, i)| *i == layer);
        chart.draw_series(
            outlines
                .clone()
                .map(|(o, i)| Polygon::new(o.clone(), colour(*i).mix(0.3))),
        )?;
        chart.draw_series(outlines.map(|(o, i)| {
            let mut closed = o.clone();
            closed.extend(o.first().copied());
            PathElement::new(closed, colour(*i).mix(0.8).stroke_width(1))
        }))?;
        chart.draw_series(
            projected
                .dots
                .iter()
                .filter(|(_, i)| *i == layer)
                .map(|(p, i)| Circle::new(*p, 2, colour(*i).filled())),
        )?;
    }
    chart.draw_series(
        projected
            .cloud
            .iter()
            .map(|p| Circle::new(*p, 2, CLOUD.mix(0.5).filled())),
    )?;
    if let (Some(first), Some(last)) = (projected.path.first(), projected.path.last()) {
        chart.draw_series(std::iter::once(PathElement::new(
            projected.path.clone(),
            PATH.stroke_width(2),
        )))?;
        chart.draw_series(std::iter::once(Circle::new(*first, 5, PATH.filled())))?;
        chart.draw_series(std::iter::once(TriangleMarker::new(
            *last,
            7,
            PATH.filled(),
        )))?;
    }
    if let Some(t) = projected.target {
        chart.draw_series(std::iter::once(Cross::new(t, 8, TARGET.stroke_width(2))))?;
    }
    Ok(())
}

/// One row of legend entries under the panels.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    picture: &ScenePicture,
) -> DrawResult<DB> {
    #[derive(Clone, Copy)]
    enum Marker {
        Swatch(RGBColor),
        Dot(RGBColor),
        Line(RGBColor),
        Cross(RGBColor),
    }
    let any_intruder = picture
        .intruder
        .iter()
        .take(picture.obstacles.len())
        .any(|&i| i);
    let mut entries = vec![(Marker::Swatch(SCENE), picture.scene_label.clone())];
    if any_intruder {
        entries.push((Marker::Swatch(INTRUDER), "intruder".to_string()));
    }
    entries.push((
        Marker::Dot(CLOUD),
        format!("sensed cloud ({} points)", picture.cloud.len()),
    ));
    if picture.tcp_path.is_some() {
        entries.push((
            Marker::Line(PATH),
            "TCP path (disc: start, triangle: end)".to_string(),
        ));
    }
    if picture.target.is_some() {
        entries.push((Marker::Cross(TARGET), "target".to_string()));
    }
    let style = TextStyle::from(("sans-serif", 16));
    let y = (LEGEND_PX / 2) as i32;
    let mut x = 40;
    for (marker, label) in entries {
        match marker {
            Marker::Swatch(c) => area.draw(&Rectangle::new(
                [(x, y - 7), (x + 24, y + 7)],
                c.mix(0.45).filled(),
            ))?,
            Marker::Dot(c) => area.draw(&Circle::new((x + 12, y), 4, c.filled()))?,
            Marker::Line(c) => area.draw(&PathElement::new(
                vec![(x, y), (x + 24, y)],
                c.stroke_width(2),
            ))?,
            Marker::Cross(c) => area.draw(&Cross::new((x + 12, y), 7, c.stroke_width(2)))?,
        }
        area.draw(&Text::new(label.clone(), (x + 32, y - 9), style.clone()))?;
        let (text_w, _) = area.estimate_text_size(&label, &style)?;
        x += 32 + text_w as i32 + 36;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Capsule, Sphere};

    #[test]
    fn a_panel_keeps_one_scale_on_both_axes_and_the_margin() {
        let (xs, ys) = equal_scale_ranges(Some([0.0, 0.4, -0.1, 0.0]), (800, 400));
        let (w, h) = (xs.end - xs.start, ys.end - ys.start);
        assert!((w / 800.0 - h / 400.0).abs() < 1e-12, "{w} x {h}");
        assert!(xs.start <= -MARGIN_M + 1e-12 && xs.end >= 0.4 + MARGIN_M - 1e-12);
        assert!(ys.start <= -0.1 - MARGIN_M + 1e-12 && ys.end >= MARGIN_M - 1e-12);
        let hull = convex_hull([(0.0, 0.0), (1.0, 0.0), (0.5, 0.2), (1.0, 1.0), (0.0, 1.0)]);
        assert_eq!(hull.len(), 4, "{hull:?}");
    }

    #[test]
    fn a_tiny_scene_is_drawn_as_png_and_svg() {
        let dir = tempfile::tempdir().unwrap();
        let obstacles = [
            Obstacle {
                id: "berry".into(),
                shape: ObstacleShape::Sphere(Sphere {
                    center: [0.5, 0.0, 0.4],
                    radius: 0.015,
                }),
            },
            Obstacle {
                id: "stem".into(),
                shape: ObstacleShape::Capsule(Capsule {
                    a: [0.45, 0.05, 0.35],
                    b: [0.45, 0.05, 0.5],
                    radius: 0.003,
                }),
            },
        ];
        let cloud = [[0.49, 0.01, 0.41], [0.46, 0.04, 0.42], [0.52, -0.03, 0.38]];
        let path = [[0.3, 0.0, 0.5], [0.38, 0.01, 0.45], [0.42, 0.0, 0.41]];
        let picture = ScenePicture {
            title: "tiny scene".into(),
            scene_label: "true scene".into(),
            obstacles: &obstacles,
            intruder: &[false, true],
            cloud: &cloud,
            tcp_path: Some(&path[..]),
            target: Some([0.5, 0.0, 0.4]),
        };
        for name in ["scene.png", "scene.svg"] {
            let file = dir.path().join(name);
            scene_picture(&file, &picture).unwrap();
            let len = std::fs::metadata(&file).unwrap().len();
            assert!(len > 0, "{name} is empty");
        }
        let svg = std::fs::read_to_string(dir.path().join("scene.svg")).unwrap();
        assert!(svg.contains("sensed cloud (3 points)"), "no legend");
        // Each cloud point once per panel, and the legend's dot.
        let cloud_fill = format!("fill=\"#{:02X}{:02X}{:02X}\"", CLOUD.0, CLOUD.1, CLOUD.2);
        assert_eq!(svg.matches(&cloud_fill).count(), 2 * cloud.len() + 1);
    }
}
