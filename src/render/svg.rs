//! SVG pictures of maps: actual segments solid, virtual ones dashed, the
//! trajectory, the final pose and a scale bar.
//!
//! The picture is in the map frame (x right, y up); SVG's y axis points
//! down, so every y is negated on output.

use std::fmt::Write as _;

use crate::geometry::Pose2;

/// How a segment is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentStyle {
    /// A wall seen by the laser: solid black.
    Actual,
    /// A frontier of the explored region: dashed.
    Virtual,
    /// A loop closure between two keyframes: thin, orange.
    LoopEdge,
}

/// A picture under construction. Coordinates in metres, map frame.
#[derive(Debug, Default, Clone)]
pub struct MapPicture {
    segments: Vec<([f64; 2], [f64; 2], SegmentStyle)>,
    trajectory: Vec<[f64; 2]>,
    pose: Option<Pose2>,
    title: Option<String>,
}

/// Pixels per metre when the picture is shown at its natural size.
const PX_PER_M: f64 = 40.0;
/// Largest side of the picture at its natural size (px).
const MAX_PX: f64 = 4000.0;
/// Margin around the drawing (m).
const MARGIN_M: f64 = 1.0;

impl MapPicture {
    pub fn new() -> Self {
        Self::default()
    }

    /// A caption drawn in the top-left corner.
    pub fn title(mut self, title: impl Into<String>) -> Self {
        self.title = Some(title.into());
        self
    }

    pub fn segment(&mut self, start: [f64; 2], end: [f64; 2], style: SegmentStyle) {
        self.segments.push((start, end, style));
    }

    /// The robot path, one entry per pose.
    pub fn trajectory(&mut self, poses: impl IntoIterator<Item = Pose2>) {
        self.trajectory = poses.into_iter().map(|p| [p.x, p.y]).collect();
    }

    /// The robot's last pose, drawn as an arrow.
    pub fn pose(&mut self, pose: Pose2) {
        self.pose = Some(pose);
    }

    /// Bounding box of everything drawn: (min, max) in metres, or a unit
    /// box around the origin for an empty picture.
    fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let points = self
            .segments
            .iter()
            .flat_map(|(a, b, _)| [*a, *b])
            .chain(self.trajectory.iter().copied())
            .chain(self.pose.map(|p| [p.x, p.y]))
            .filter(|p| p[0].is_finite() && p[1].is_finite());
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        for p in points {
            for k in 0..2 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        if min[0] > max[0] {
            return ([-1.0, -1.0], [1.0, 1.0]);
        }
        (min, max)
    }

    /// Renders the picture as a standalone SVG document.
    pub fn to_svg(&self) -> String {
        let (min, max) = self.bounds();
        let x0 = min[0] - MARGIN_M;
        let y0 = -(max[1] + MARGIN_M);
        let w = (max[0] - min[0]) + 2.0 * MARGIN_M;
        let h = (max[1] - min[1]) + 2.0 * MARGIN_M;
        // Line widths in metres, scaled so that large maps stay legible.
        let stroke = (w.max(h) / 800.0).max(0.02);
        // Natural size, shrunk so the larger side stays within MAX_PX.
        let px_per_m = PX_PER_M.min(MAX_PX / w.max(h));
        let mut s = String::new();
        // Writing to a String cannot fail; the results are ignored on purpose.
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="{x0:.3} {y0:.3} {w:.3} {h:.3}" width="{:.0}" height="{:.0}">"#,
            w * px_per_m,
            h * px_per_m
        );
        let _ = writeln!(
            s,
            r#"<rect x="{x0:.3}" y="{y0:.3}" width="{w:.3}" height="{h:.3}" fill="white"/>"#
        );
        if self.trajectory.len() > 1 {
            let mut d = String::new();
            for (i, p) in self.trajectory.iter().enumerate() {
                let _ = write!(
                    d,
                    "{}{:.3},{:.3} ",
                    if i == 0 { "M" } else { "L" },
                    p[0],
                    -p[1]
                );
            }
            let _ = writeln!(
                s,
                r##"<path d="{}" fill="none" stroke="#1f77b4" stroke-width="{:.3}" stroke-opacity="0.7"/>"##,
                d.trim_end(),
                stroke
            );
        }
        for (a, b, style) in &self.segments {
            let extra = match style {
                SegmentStyle::Actual => {
                    format!(r#"stroke="black" stroke-width="{:.3}""#, stroke * 2.0)
                }
                SegmentStyle::LoopEdge => format!(
                    r##"stroke="#ff7f0e" stroke-width="{:.3}" stroke-opacity="0.8""##,
                    stroke * 0.7
                ),
                SegmentStyle::Virtual => format!(
                    r##"stroke="#d62728" stroke-width="{:.3}" stroke-dasharray="{:.3} {:.3}""##,
                    stroke,
                    stroke * 6.0,
                    stroke * 4.0
                ),
            };
            let _ = writeln!(
                s,
                r#"<line x1="{:.3}" y1="{:.3}" x2="{:.3}" y2="{:.3}" {extra} stroke-linecap="round"/>"#,
                a[0], -a[1], b[0], -b[1]
            );
        }
        if let Some(p) = self.pose {
            let r = (w.max(h) / 60.0).max(0.2);
            let tip = p.transform_point([r, 0.0]);
            let left = p.transform_point([-r * 0.6, r * 0.5]);
            let right = p.transform_point([-r * 0.6, -r * 0.5]);
            let _ = writeln!(
                s,
                r##"<polygon points="{:.3},{:.3} {:.3},{:.3} {:.3},{:.3}" fill="#2ca02c"/>"##,
                tip[0], -tip[1], left[0], -left[1], right[0], -right[1]
            );
        }
        // Scale bar: the largest power of ten (or 2×, 5×) under a fifth of the width.
        let bar = nice_length(w / 5.0);
        let bx = x0 + 0.3 * MARGIN_M;
        let by = y0 + h - 0.3 * MARGIN_M;
        let font = (w.max(h) / 60.0).max(0.25);
        let _ = writeln!(
            s,
            r#"<line x1="{bx:.3}" y1="{by:.3}" x2="{:.3}" y2="{by:.3}" stroke="black" stroke-width="{:.3}"/>"#,
            bx + bar,
            stroke * 3.0
        );
        let _ = writeln!(
            s,
            r#"<text x="{bx:.3}" y="{:.3}" font-size="{font:.3}" font-family="sans-serif">{} m</text>"#,
            by - font * 0.4,
            format_length(bar)
        );
        if let Some(t) = &self.title {
            let _ = writeln!(
                s,
                r#"<text x="{:.3}" y="{:.3}" font-size="{font:.3}" font-family="sans-serif">{}</text>"#,
                x0 + 0.3 * MARGIN_M,
                y0 + 0.3 * MARGIN_M + font,
                escape_xml(t)
            );
        }
        s.push_str("</svg>\n");
        s
    }
}

/// The largest 1, 2 or 5 × 10^k not above `max` (m).
fn nice_length(max: f64) -> f64 {
    if !(max.is_finite() && max > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(max.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * p)
        .find(|&l| l <= max)
        .unwrap_or(p)
}

fn format_length(l: f64) -> String {
    if l >= 1.0 {
        format!("{l:.0}")
    } else {
        format!("{l}")
    }
}

fn escape_xml(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_every_element() {
        let mut pic = MapPicture::new().title("room <1>");
        pic.segment([0.0, 0.0], [4.0, 0.0], SegmentStyle::Actual);
        pic.segment([4.0, 0.0], [4.0, 3.0], SegmentStyle::Virtual);
        pic.trajectory([Pose2::new(1.0, 1.0, 0.0), Pose2::new(2.0, 1.5, 0.5)]);
        pic.pose(Pose2::new(2.0, 1.5, 0.5));
        let svg = pic.to_svg();
        assert!(svg.starts_with("<svg"));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert_eq!(
            svg.matches("<line").count(),
            3,
            "two segments and a scale bar"
        );
        assert_eq!(svg.matches("stroke-dasharray").count(), 1);
        assert!(svg.contains("<path d=\"M1.000,-1.000 L2.000,-1.500\""));
        assert!(svg.contains("<polygon"));
        assert!(svg.contains("room &lt;1&gt;"));
        // y is flipped: the wall at y = 0..3 is drawn at -0..-3.
        assert!(svg.contains("y2=\"-3.000\""));
    }

    #[test]
    fn empty_picture_is_valid() {
        let svg = MapPicture::new().to_svg();
        assert!(svg.contains("viewBox"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
    }

    #[test]
    fn scale_bar_lengths_are_round() {
        assert_eq!(nice_length(3.7), 2.0);
        assert_eq!(nice_length(7.0), 5.0);
        assert_eq!(nice_length(0.15), 0.1);
        assert_eq!(nice_length(10.0), 10.0);
        assert_eq!(nice_length(f64::NAN), 1.0);
    }
}
