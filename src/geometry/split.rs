//! Segmentation of a scan's points: runs at range discontinuities, recursive
//! split at the point farthest from the chord, a merge pass of collinear
//! neighbours, and assignment of each shared break point to one side.
//!
//! All index ranges are inclusive (`Span { first, last }`) into the scan's
//! valid points, and every list stays in scan order.

use super::fit::{PrefixMoments, residuals};
use super::points::ScanPoint;

/// Inclusive range of point indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Span {
    pub first: usize,
    pub last: usize,
}

impl Span {
    /// Number of points in the span.
    pub fn len(&self) -> usize {
        self.last + 1 - self.first
    }
}

/// Appends to `out` the maximal runs of `points` in which consecutive points
/// are at most `max_gap` metres apart (an occlusion or a missing stretch of
/// wall ends a run).
pub(crate) fn split_runs(points: &[ScanPoint], max_gap: f64, out: &mut Vec<Span>) {
    if points.is_empty() {
        return;
    }
    let max_gap_sq = max_gap * max_gap;
    let mut first = 0;
    for i in 1..points.len() {
        let (a, b) = (points[i - 1].p, points[i].p);
        let gap_sq = (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2);
        if gap_sq > max_gap_sq || gap_sq.is_nan() {
            out.push(Span { first, last: i - 1 });
            first = i;
        }
    }
    out.push(Span {
        first,
        last: points.len() - 1,
    });
}

/// Index and distance of the interior point of `span` farthest from the
/// chord joining its first and last points.
fn farthest_from_chord(points: &[ScanPoint], span: Span) -> (usize, f64) {
    let a = points[span.first].p;
    let b = points[span.last].p;
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    let mut best = (span.first, 0.0);
    for (k, sp) in points[span.first + 1..span.last]
        .iter()
        .enumerate()
        .map(|(k, sp)| (k + span.first + 1, sp))
    {
        let (px, py) = (sp.p[0] - a[0], sp.p[1] - a[1]);
        // Cross product over chord length; a closed chord (first == last
        // point) falls back to the distance from that point.
        let d = if len > 1e-12 {
            (dx * py - dy * px).abs() / len
        } else {
            px.hypot(py)
        };
        if d > best.1 {
            best = (k, d);
        }
    }
    best
}

/// Splits `s` at `k` (both halves keep it) onto `stack`, right half first
/// so the left half is popped, and emitted, first: pieces stay in scan order.
fn push_halves(stack: &mut Vec<Span>, s: Span, k: usize) {
    stack.push(Span {
        first: k,
        last: s.last,
    });
    stack.push(Span {
        first: s.first,
        last: k,
    });
}

/// Recursively splits `span` at the point farthest from its chord while
/// that distance exceeds `threshold`; appends the pieces to `out` in scan
/// order. Neighbouring pieces share their break point. `stack` is scratch
/// space, passed in so repeated calls do not allocate.
pub(crate) fn split_recursive(
    points: &[ScanPoint],
    span: Span,
    threshold: f64,
    stack: &mut Vec<Span>,
    out: &mut Vec<Span>,
) {
    stack.clear();
    stack.push(span);
    while let Some(s) = stack.pop() {
        if s.last < s.first + 2 {
            out.push(s);
            continue;
        }
        let (k, d) = farthest_from_chord(points, s);
        if d > threshold {
            push_halves(stack, s, k);
        } else {
            out.push(s);
        }
    }
}

/// When a span's fitted line is accepted as one straight wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LineTest {
    /// Every point within this distance of the fitted line (m).
    pub max_distance: f64,
    /// Reduced χ² of the fit at most this (see `FitResiduals`).
    pub max_chi2: f64,
    /// Floor on a point's across-line σ in the χ² (m).
    pub sigma_floor: f64,
}

/// Splits further every span whose fitted line is statistically not one
/// line (reduced χ² above `test.max_chi2`), at the interior point farthest
/// from the fitted line, as long as both halves keep `min_points`. The
/// chord test misses a shallow step (a door recess seen from afar under a
/// split threshold sized for noisy data); the residuals do not.
pub(crate) fn split_by_fit(
    points: &[ScanPoint],
    moments: &PrefixMoments,
    test: &LineTest,
    min_points: usize,
    spans: &[Span],
    stack: &mut Vec<Span>,
    out: &mut Vec<Span>,
) {
    for &span in spans {
        stack.clear();
        stack.push(span);
        while let Some(s) = stack.pop() {
            let split_at = (s.len() >= 2 * min_points)
                .then(|| moments.fit(s.first, s.last))
                .flatten()
                .map(|fit| residuals(&points[s.first..=s.last], &fit, test.sigma_floor))
                .filter(|r| r.chi2_per_dof > test.max_chi2)
                .and_then(|r| r.farthest_interior)
                .map(|k| s.first + k)
                .filter(|&k| k + 1 >= s.first + min_points && s.last + 1 >= k + min_points);
            match split_at {
                Some(k) => push_halves(stack, s, k),
                None => out.push(s),
            }
        }
    }
}

/// One left-to-right pass merging each span into its predecessor when the
/// two touch (share a break point) and the total-least-squares line of the
/// union passes `test`. This undoes splits that noise caused on a straight
/// wall.
pub(crate) fn merge_collinear(
    points: &[ScanPoint],
    moments: &PrefixMoments,
    test: &LineTest,
    spans: &mut Vec<Span>,
) {
    let mut write = 0;
    for read in 0..spans.len() {
        let next = spans[read];
        if read > 0 {
            let cur = spans[write];
            if next.first == cur.last {
                let union = Span {
                    first: cur.first,
                    last: next.last,
                };
                let pts = &points[union.first..=union.last];
                if let Some(fit) = moments.fit(union.first, union.last)
                    && let r = residuals(pts, &fit, test.sigma_floor)
                    && r.max_distance <= test.max_distance
                    && r.chi2_per_dof <= test.max_chi2
                {
                    spans[write] = union;
                    continue;
                }
            }
            write += 1;
        }
        spans[write] = next;
    }
    spans.truncate(if spans.is_empty() { 0 } else { write + 1 });
}

/// Gives each break point shared by two neighbouring spans to the side
/// whose line (fitted without it) passes closer, so a corner point does not
/// bias the wall it does not belong to.
pub(crate) fn assign_break_points(
    points: &[ScanPoint],
    moments: &PrefixMoments,
    spans: &mut [Span],
) {
    for i in 1..spans.len() {
        let (a, b) = (spans[i - 1], spans[i]);
        if a.last != b.first {
            continue;
        }
        let k = a.last;
        let p = points[k].p;
        let dist = |first: usize, last: usize| {
            moments
                .fit(first, last)
                .map_or(f64::INFINITY, |f| f.distance(p))
        };
        // A side with fewer than two other points cannot be fitted.
        let d_left = if k >= a.first + 2 {
            dist(a.first, k - 1)
        } else {
            f64::INFINITY
        };
        let d_right = if b.last >= k + 2 {
            dist(k + 1, b.last)
        } else {
            f64::INFINITY
        };
        if d_left <= d_right && b.len() >= 2 {
            spans[i].first = k + 1;
        } else if a.len() >= 2 {
            spans[i - 1].last = k - 1;
        }
    }
}

/// Largest number of points [`trim_ends`] removes from each end of a span.
const MAX_TRIM_PER_END: usize = 3;

/// Drops end points that do not belong to their span's line: a point is
/// dropped when its distance from the line fitted to the rest of the span
/// exceeds `sigmas` times its across-line noise (`σ_r·|n·u|`), and at least
/// `floor` metres. This removes the first point of the next surface that a
/// corner leaves within the split threshold of the chord (it would tilt a
/// short line by about a degree), and mixed pixels at occlusion edges.
/// At most [`MAX_TRIM_PER_END`] points go from each end; spans never drop
/// below three points.
pub(crate) fn trim_ends(
    points: &[ScanPoint],
    moments: &PrefixMoments,
    sigmas: f64,
    floor: f64,
    spans: &mut [Span],
) {
    // Distance of point k from the line through first..=last, relative to
    // its trimming threshold (> 1: trim).
    let excess = |k: usize, first: usize, last: usize| {
        let fit = moments.fit(first, last)?;
        let sp = &points[k];
        let n = [-fit.direction[1], fit.direction[0]];
        let across = sp.sigma_range * (n[0] * sp.beam[0] + n[1] * sp.beam[1]).abs();
        Some(fit.distance(sp.p) / (sigmas * across).max(floor))
    };
    for span in spans.iter_mut() {
        let (mut trimmed_first, mut trimmed_last) = (0, 0);
        // Trim the worse end first: a stray point at one end tilts the fit
        // that judges the other end.
        while span.len() > 3 {
            let first_excess = (trimmed_first < MAX_TRIM_PER_END)
                .then(|| excess(span.first, span.first + 1, span.last))
                .flatten();
            let last_excess = (trimmed_last < MAX_TRIM_PER_END)
                .then(|| excess(span.last, span.first, span.last - 1))
                .flatten();
            match (first_excess, last_excess) {
                (Some(f), l) if f > 1.0 && l.is_none_or(|l| f >= l) => {
                    span.first += 1;
                    trimmed_first += 1;
                }
                (_, Some(l)) if l > 1.0 => {
                    span.last -= 1;
                    trimmed_last += 1;
                }
                _ => break,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test(max_distance: f64) -> LineTest {
        LineTest {
            max_distance,
            max_chi2: 4.0,
            sigma_floor: 0.001,
        }
    }

    fn pts(xy: &[[f64; 2]]) -> Vec<ScanPoint> {
        xy.iter()
            .map(|&p| ScanPoint {
                p,
                beam: [1.0, 0.0],
                sigma_range: 0.01,
                beam_index: 0,
            })
            .collect()
    }

    /// An L-shaped corner: 10 points along x = 2 going up, then 10 along
    /// y = 1 going left; the corner point is shared.
    fn corner() -> Vec<ScanPoint> {
        let mut xy: Vec<[f64; 2]> = (0..=10).map(|i| [2.0, -1.0 + 0.2 * i as f64]).collect();
        xy.extend((1..=10).map(|i| [2.0 - 0.2 * i as f64, 1.0]));
        pts(&xy)
    }

    #[test]
    fn runs_break_at_gaps() {
        let p = pts(&[[1.0, 0.0], [1.0, 0.1], [1.0, 0.9], [1.0, 1.0]]);
        let mut runs = Vec::new();
        split_runs(&p, 0.5, &mut runs);
        assert_eq!(
            runs,
            vec![Span { first: 0, last: 1 }, Span { first: 2, last: 3 }]
        );
    }

    #[test]
    fn corner_splits_into_two_lines_and_the_corner_goes_to_one_side() {
        let p = corner();
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let (mut stack, mut out) = (Vec::new(), Vec::new());
        let span = Span {
            first: 0,
            last: p.len() - 1,
        };
        split_recursive(&p, span, 0.05, &mut stack, &mut out);
        assert_eq!(
            out,
            vec![
                Span { first: 0, last: 10 },
                Span {
                    first: 10,
                    last: 20
                }
            ]
        );
        merge_collinear(&p, &m, &test(0.05), &mut out);
        assert_eq!(out.len(), 2, "a corner is not collinear");
        assign_break_points(&p, &m, &mut out);
        // Point 10 is exactly on both lines: it goes left (ties go left).
        assert_eq!(
            out,
            vec![
                Span { first: 0, last: 10 },
                Span {
                    first: 11,
                    last: 20
                }
            ]
        );
    }

    #[test]
    fn trims_a_point_of_the_next_surface() {
        // Regression (room, seed 22): a box face x = 5.9 scanned to its
        // corner, then one point 2.5 cm away on the grazing top face.
        let mut xy: Vec<[f64; 2]> = (0..15).map(|i| [5.9, 1.0 + 0.04 * i as f64]).collect();
        xy.push([5.9254, 1.6]);
        let mut p = pts(&xy);
        for sp in &mut p {
            sp.sigma_range = 0.0;
        }
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let mut spans = vec![Span { first: 0, last: 15 }];
        trim_ends(&p, &m, 3.0, 0.001, &mut spans);
        assert_eq!(spans, vec![Span { first: 0, last: 14 }]);
        // With 1 cm range noise the point is within 3σ and stays.
        for sp in &mut p {
            sp.sigma_range = 0.01;
        }
        let mut spans = vec![Span { first: 0, last: 15 }];
        trim_ends(&p, &m, 3.0, 0.001, &mut spans);
        assert_eq!(spans, vec![Span { first: 0, last: 15 }]);
    }

    #[test]
    fn splits_a_shallow_step_the_chord_test_misses() {
        // A wall at y = 1 with a 10 cm deep recess over its last third:
        // within a 10 cm chord threshold, but 10σ at 1 cm noise.
        let xy: Vec<[f64; 2]> = (0..30)
            .map(|i| [0.1 * i as f64, if i < 20 { 1.0 } else { 1.1 }])
            .collect();
        let mut p = pts(&xy);
        for sp in &mut p {
            sp.beam = [0.0, 1.0];
        }
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let whole = [Span { first: 0, last: 29 }];
        let (mut stack, mut out) = (Vec::new(), Vec::new());
        split_recursive(&p, whole[0], 0.1, &mut stack, &mut out);
        assert_eq!(out, whole, "the chord test alone keeps it whole");
        out.clear();
        split_by_fit(&p, &m, &test(0.1), 6, &whole, &mut stack, &mut out);
        assert!(out.len() >= 2, "{out:?}");
        // The pieces are lines again and do not merge back.
        merge_collinear(&p, &m, &test(0.1), &mut out);
        assert!(out.len() >= 2, "{out:?}");
    }

    #[test]
    fn merge_joins_collinear_pieces() {
        let xy: Vec<[f64; 2]> = (0..30).map(|i| [3.0, 0.1 * i as f64]).collect();
        let p = pts(&xy);
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let mut spans = vec![
            Span { first: 0, last: 9 },
            Span { first: 9, last: 19 },
            Span {
                first: 19,
                last: 29,
            },
        ];
        merge_collinear(&p, &m, &test(0.01), &mut spans);
        assert_eq!(spans, vec![Span { first: 0, last: 29 }]);
    }
}
