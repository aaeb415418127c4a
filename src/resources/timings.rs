//! Wall-clock timings of each system set in recent steps, for the progress display, the
//! summary and the viewer's schedule panel.

use std::collections::BTreeMap;
use std::time::Duration;

use bevy_ecs::prelude::*;

/// How many recent samples each timing keeps.
const HISTORY: usize = 4096;

/// Durations per system set (and for resampling alone), most recent last.
#[derive(Resource, Clone, Debug, Default)]
pub struct StepTimings {
    per_set: BTreeMap<&'static str, Vec<Duration>>,
    /// How many durations were ever recorded under each name (the history keeps the last
    /// [`HISTORY`] only).
    recorded: BTreeMap<&'static str, u64>,
    /// When the set being timed started.
    pub(crate) started: Option<std::time::Instant>,
}

impl StepTimings {
    /// Records one duration under `name`.
    pub fn record(&mut self, name: &'static str, d: Duration) {
        *self.recorded.entry(name).or_default() += 1;
        let v = self.per_set.entry(name).or_default();
        if v.len() == HISTORY {
            v.remove(0);
        }
        v.push(d);
    }
    /// Records the stages a pass timed itself: `names[k]` took `ms[k]` milliseconds (negative
    /// or NaN read as 0).
    pub fn record_ms(&mut self, names: &[&'static str], ms: &[f64]) {
        for (&name, &ms) in names.iter().zip(ms) {
            let ms = if ms > 0.0 { ms } else { 0.0 };
            self.record(name, Duration::from_secs_f64(ms * 1e-3));
        }
    }
    /// The most recent duration recorded under `name`.
    pub fn last(&self, name: &str) -> Option<Duration> {
        self.per_set.get(name).and_then(|v| v.last().copied())
    }
    /// How many durations were ever recorded under `name` (0 if none): a name recorded during
    /// a step has a larger count after it.
    pub fn recorded(&self, name: &str) -> u64 {
        self.recorded.get(name).copied().unwrap_or(0)
    }
    /// Median of the recorded durations under `name`, milliseconds.
    pub fn median_ms(&self, name: &str) -> Option<f64> {
        let v = self.per_set.get(name)?;
        if v.is_empty() {
            return None;
        }
        let mut ms: Vec<f64> = v.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        ms.sort_by(f64::total_cmp);
        let n = ms.len();
        Some(if n % 2 == 1 {
            ms[n / 2]
        } else {
            0.5 * (ms[n / 2 - 1] + ms[n / 2])
        })
    }
    /// How many durations are recorded under `name` (at most the history kept).
    pub fn count(&self, name: &str) -> usize {
        self.per_set.get(name).map_or(0, Vec::len)
    }
    /// Mean of the durations recorded under `name` from the `from`-th to the one before the
    /// `to`-th (in recording order), milliseconds: what a set costs a step on average over
    /// those steps when it runs only on some of them (the surface processes with
    /// `time.relief_interval_steps` above 1), where the median says nothing.
    pub fn mean_ms(&self, name: &str, from: usize, to: usize) -> Option<f64> {
        let v = self.per_set.get(name)?;
        let v = v.get(from..to.min(v.len()))?;
        if v.is_empty() {
            return None;
        }
        Some(v.iter().map(|d| d.as_secs_f64() * 1e3).sum::<f64>() / v.len() as f64)
    }
    /// Names with recorded timings.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.per_set.keys().copied()
    }
    /// Forgets everything recorded.
    pub fn clear(&mut self) {
        self.per_set.clear();
    }
}
