//! Per-stage latency histograms of the real-time loop.
//!
//! HDR histograms (1 µs to 60 s at 3 significant digits, a few tens of KiB
//! each, constant memory): a mean hides the one slow scan in a thousand
//! that makes a robot overshoot; p99 and the maximum do not.

use std::time::Duration;

use hdrhistogram::Histogram;
use serde::Serialize;

/// The stages measured, in pipeline order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Stage {
    /// The telegram's last byte to the loop taking the scan up.
    Queue,
    /// Odometry prediction.
    Predict,
    /// Line extraction.
    Extract,
    /// Local localization against the map.
    Localize,
    /// Segment map update (keyframes).
    MapUpdate,
    /// CLS map update (keyframes).
    ClsUpdate,
    /// End to end: the telegram's last byte to the corrected pose.
    Pose,
    /// Exploration planning and path following, per control tick.
    Control,
}

impl Stage {
    pub const ALL: [Stage; 8] = [
        Stage::Queue,
        Stage::Predict,
        Stage::Extract,
        Stage::Localize,
        Stage::MapUpdate,
        Stage::ClsUpdate,
        Stage::Pose,
        Stage::Control,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Queue => "queue",
            Stage::Predict => "predict",
            Stage::Extract => "extract",
            Stage::Localize => "localize",
            Stage::MapUpdate => "map_update",
            Stage::ClsUpdate => "cls_update",
            Stage::Pose => "last_byte_to_pose",
            Stage::Control => "control",
        }
    }
}

/// Quantiles of one stage (µs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StageSummary {
    pub stage: Stage,
    pub count: u64,
    pub p50_us: u64,
    pub p99_us: u64,
    pub max_us: u64,
    pub mean_us: f64,
}

/// One histogram per [`Stage`].
#[derive(Debug, Clone)]
pub struct Latencies {
    histograms: Vec<Histogram<u64>>,
}

/// Largest value recorded (µs); longer ones are clamped to it.
const MAX_US: u64 = 60_000_000;

impl Default for Latencies {
    fn default() -> Self {
        Latencies::new()
    }
}

impl Latencies {
    pub fn new() -> Latencies {
        let histograms = Stage::ALL
            .iter()
            // Constant, valid bounds: this cannot fail.
            .map(|_| Histogram::new_with_bounds(1, MAX_US, 3).expect("valid histogram bounds"))
            .collect();
        Latencies { histograms }
    }

    /// Records one duration of `stage`.
    pub fn record(&mut self, stage: Stage, d: Duration) {
        let us = (d.as_micros().min(u128::from(MAX_US)) as u64).max(1);
        if let Some(h) = self.histograms.get_mut(stage as usize) {
            h.saturating_record(us);
        }
    }

    /// Quantiles of `stage`, or `None` before its first record.
    pub fn summary(&self, stage: Stage) -> Option<StageSummary> {
        let h = self.histograms.get(stage as usize)?;
        (!h.is_empty()).then(|| StageSummary {
            stage,
            count: h.len(),
            p50_us: h.value_at_quantile(0.5),
            p99_us: h.value_at_quantile(0.99),
            max_us: h.max(),
            mean_us: h.mean(),
        })
    }

    /// Quantiles of every stage that ran.
    pub fn summaries(&self) -> Vec<StageSummary> {
        Stage::ALL.iter().filter_map(|s| self.summary(*s)).collect()
    }

    /// One line for the log: `stage p50/p99/max µs`, stages that ran.
    pub fn line(&self) -> String {
        self.summaries()
            .iter()
            .map(|s| format!("{} {}/{}/{}", s.stage.name(), s.p50_us, s.p99_us, s.max_us))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_follow_the_records() {
        let mut l = Latencies::new();
        assert!(l.summary(Stage::Pose).is_none());
        for us in 1..=1000u64 {
            l.record(Stage::Pose, Duration::from_micros(us));
        }
        l.record(Stage::Pose, Duration::from_secs(3600));
        let s = l.summary(Stage::Pose).unwrap_or_else(|| panic!("recorded"));
        assert_eq!(s.count, 1001);
        assert!((495..=505).contains(&s.p50_us), "{s:?}");
        assert!((985..=1000).contains(&s.p99_us), "{s:?}");
        assert!(s.max_us >= 59_900_000, "clamped to 60 s: {s:?}");
        assert!(l.line().starts_with("last_byte_to_pose "));
        assert_eq!(l.summaries().len(), 1);
    }
}
