//! The profiler: a `tracing-subscriber` layer that times spans and sums them per place
//! in the span tree, so `--profile`, `summary.json` and `--trace` all come from the
//! same spans. The runner opens a `step` span per step and a `stage` span (field
//! `name`) around every stage call; stages open inner spans (`grid_build`, `scan`,
//! file writes, ...) on the thread that calls them, which appear under their stage.
//!
//! A span's row is its `name` field when it has one (the runner's stage spans), else
//! its span name; rows are keyed by their path from the root, so `scan` under
//! `neighbour_grid` and a `scan` elsewhere are separate rows. A call is one span (from
//! creation to close); its time is the time it was entered (busy time), so a span
//! entered again while entered, or on two threads at once, counts the covered time
//! once.
//!
//! The layer is only installed when a run is profiled: without a subscriber the spans
//! cost an atomic load each.

use serde::Serialize;
use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tracing::field::{Field, Visit};
use tracing::span;
use tracing::Subscriber;
use tracing_subscriber::layer::{Context, Layer};
use tracing_subscriber::registry::LookupSpan;

/// The totals of one row of the profile: a span path's calls and busy time, with the
/// rows of the spans opened inside it.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SpanTime {
    pub span: String,
    pub calls: u64,
    pub seconds: f64,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub inner: Vec<SpanTime>,
}

impl SpanTime {
    /// The row directly inside this one labelled `label`.
    pub fn child(&self, label: &str) -> Option<&SpanTime> {
        self.inner.iter().find(|s| s.span == label)
    }
}

/// One row while the run goes on.
#[derive(Debug)]
struct Node {
    label: String,
    children: Vec<usize>,
    calls: u64,
    busy: Duration,
}

/// The rows, in the order their first span was created.
#[derive(Debug, Default)]
struct Tree {
    nodes: Vec<Node>,
    roots: Vec<usize>,
}

impl Tree {
    /// The row `label` under `parent` (a root without one), created if new.
    fn row(&mut self, parent: Option<usize>, label: &str) -> usize {
        let siblings = match parent {
            Some(p) => &self.nodes[p].children,
            None => &self.roots,
        };
        if let Some(&k) = siblings.iter().find(|&&k| self.nodes[k].label == label) {
            return k;
        }
        let k = self.nodes.len();
        self.nodes.push(Node {
            label: label.to_string(),
            children: Vec::new(),
            calls: 0,
            busy: Duration::ZERO,
        });
        match parent {
            Some(p) => self.nodes[p].children.push(k),
            None => self.roots.push(k),
        }
        k
    }

    fn report(&self, k: usize) -> SpanTime {
        let n = &self.nodes[k];
        SpanTime {
            span: n.label.clone(),
            calls: n.calls,
            seconds: n.busy.as_secs_f64(),
            inner: n.children.iter().map(|&c| self.report(c)).collect(),
        }
    }
}

/// The per-span state, kept in the span's extensions.
struct Timing {
    row: usize,
    busy: Duration,
    /// Enters not yet exited, and when the first of them began.
    open: u32,
    since: Option<Instant>,
}

/// The layer; install it with `tracing_subscriber::registry().with(layer)`.
pub struct ProfileLayer {
    tree: Arc<Mutex<Tree>>,
}

/// The handle that reads the totals of its [`ProfileLayer`].
#[derive(Clone)]
pub struct Profile {
    tree: Arc<Mutex<Tree>>,
}

impl ProfileLayer {
    /// A layer and the handle to read its totals.
    pub fn new() -> (ProfileLayer, Profile) {
        let tree = Arc::new(Mutex::new(Tree::default()));
        (ProfileLayer { tree: tree.clone() }, Profile { tree })
    }

    fn tree(&self) -> MutexGuard<'_, Tree> {
        // A panic elsewhere while the lock was held leaves consistent totals (every
        // update is a single push or add), so a poisoned lock is still usable.
        self.tree.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Profile {
    /// The rows of the spans closed so far, top-level spans first, each with the rows
    /// opened inside it.
    pub fn report(&self) -> Vec<SpanTime> {
        let tree = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        tree.roots.iter().map(|&k| tree.report(k)).collect()
    }
}

/// Reads a span's `name` field.
#[derive(Default)]
struct Label(Option<String>);

impl Visit for Label {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "name" {
            self.0 = Some(value.to_string());
        }
    }
    fn record_debug(&mut self, field: &Field, value: &dyn fmt::Debug) {
        if field.name() == "name" {
            self.0 = Some(format!("{value:?}"));
        }
    }
}

impl<S> Layer<S> for ProfileLayer
where
    S: Subscriber + for<'a> LookupSpan<'a>,
{
    fn on_new_span(&self, attrs: &span::Attributes<'_>, id: &span::Id, ctx: Context<'_, S>) {
        let Some(span) = ctx.span(id) else {
            return;
        };
        let parent = span
            .parent()
            .and_then(|p| p.extensions().get::<Timing>().map(|t| t.row));
        let mut label = Label::default();
        attrs.record(&mut label);
        let label = label.0.as_deref().unwrap_or(attrs.metadata().name());
        let row = self.tree().row(parent, label);
        span.extensions_mut().insert(Timing {
            row,
            busy: Duration::ZERO,
            open: 0,
            since: None,
        });
    }

    fn on_enter(&self, id: &span::Id, ctx: Context<'_, S>) {
        let Some(span) = ctx.span(id) else {
            return;
        };
        let mut ext = span.extensions_mut();
        if let Some(t) = ext.get_mut::<Timing>() {
            if t.open == 0 {
                t.since = Some(Instant::now());
            }
            t.open = t.open.saturating_add(1);
        }
    }

    fn on_exit(&self, id: &span::Id, ctx: Context<'_, S>) {
        let Some(span) = ctx.span(id) else {
            return;
        };
        let mut ext = span.extensions_mut();
        if let Some(t) = ext.get_mut::<Timing>() {
            t.open = t.open.saturating_sub(1);
            if t.open == 0 {
                if let Some(since) = t.since.take() {
                    t.busy += since.elapsed();
                }
            }
        }
    }

    fn on_close(&self, id: span::Id, ctx: Context<'_, S>) {
        let Some(span) = ctx.span(&id) else {
            return;
        };
        let Some(t) = span.extensions_mut().remove::<Timing>() else {
            return;
        };
        // A span closed while entered (not possible through the `tracing` API, which
        // exits before it drops) counts up to now.
        let busy = t.busy + t.since.map_or(Duration::ZERO, |s| s.elapsed());
        let mut tree = self.tree();
        let node = &mut tree.nodes[t.row];
        node.calls += 1;
        node.busy += busy;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::prelude::*;

    fn profiled(f: impl FnOnce()) -> Vec<SpanTime> {
        let (layer, profile) = ProfileLayer::new();
        let subscriber = tracing_subscriber::registry().with(layer);
        tracing::subscriber::with_default(subscriber, f);
        profile.report()
    }

    #[test]
    fn rows_follow_the_span_tree_and_the_name_field() {
        let report = profiled(|| {
            for step in 0..3 {
                let _step = tracing::info_span!("step", step).entered();
                for name in ["a", "b"] {
                    let _stage = tracing::info_span!("stage", name).entered();
                    let _inner = tracing::info_span!("inner").entered();
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
            // The same span name elsewhere in the tree is another row.
            let _outside = tracing::info_span!("inner").entered();
        });
        let labels: Vec<&str> = report.iter().map(|s| s.span.as_str()).collect();
        assert_eq!(labels, ["step", "inner"]);
        let step = &report[0];
        assert_eq!(step.calls, 3);
        assert_eq!(report[1].calls, 1);
        for stage in ["a", "b"] {
            let s = step.child(stage).expect(stage);
            assert_eq!(s.calls, 3);
            let inner = s.child("inner").expect("inner");
            assert_eq!(inner.calls, 3);
            // Slept 3 x 1 ms inside; the stage holds its inner span's time.
            assert!(inner.seconds >= 3e-3, "{inner:?}");
            assert!(s.seconds >= inner.seconds, "{s:?}");
        }
        assert!(step.seconds >= step.inner.iter().map(|s| s.seconds).sum::<f64>());
    }

    #[test]
    fn time_counts_only_while_entered() {
        let report = profiled(|| {
            let span = tracing::info_span!("s");
            // Created but not entered: not counted.
            std::thread::sleep(Duration::from_millis(60));
            span.in_scope(|| {
                // Entered again while entered.
                span.in_scope(|| std::thread::sleep(Duration::from_millis(2)));
            });
        });
        assert_eq!(report.len(), 1);
        assert_eq!(report[0].calls, 1);
        let s = report[0].seconds;
        assert!((2e-3..50e-3).contains(&s), "{s}");
    }
}
