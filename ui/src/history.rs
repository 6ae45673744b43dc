//! Undo and redo of scene, sensor and elastomer edits. Every such edit is a [`Command`] (`SetScene`, `SetSim`,
//! `SetSeed`, `PickInflation`) applied in one place, so the history stores a snapshot of what they change before
//! each one; consecutive edits of the same kind within [`History::coalesce`] (a slider drag, typing a number) become
//! one step.

use std::time::{Duration, Instant};

use tactile_derender::sim::SimConfig;

use crate::command::Command;
use crate::state::{SceneState, State};

/// What scene, sensor and elastomer edits change.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    pub scene: SceneState,
    pub sim: SimConfig,
    pub seed: u64,
}

impl Snapshot {
    pub fn of(state: &State) -> Self {
        Self {
            scene: state.scene.clone(),
            sim: state.sim.clone(),
            seed: state.seed,
        }
    }

    /// Put this snapshot into `state`.
    pub fn restore(self, state: &mut State) {
        state.scene = self.scene;
        state.sim = self.sim;
        state.seed = self.seed;
    }
}

/// Which kind of edit a command is, for coalescing (`None`: not an undoable edit).
pub fn edit_kind(cmd: &Command) -> Option<&'static str> {
    match cmd {
        Command::SetScene(_) => Some("scene"),
        Command::SetSim(_) | Command::PickInflation(_) => Some("sensor"),
        Command::SetSeed(_) => Some("seed"),
        _ => None,
    }
}

/// The undo and redo stacks.
#[derive(Debug)]
pub struct History {
    undo: Vec<Snapshot>,
    redo: Vec<Snapshot>,
    /// Kind and time of the newest recorded edit.
    last: Option<(&'static str, Instant)>,
    /// Edits of one kind closer together than this are one step (default 0.6 s).
    pub coalesce: Duration,
    /// Most steps kept.
    pub limit: usize,
}

impl Default for History {
    fn default() -> Self {
        Self {
            undo: Vec::new(),
            redo: Vec::new(),
            last: None,
            coalesce: Duration::from_millis(600),
            limit: 200,
        }
    }
}

impl History {
    /// Record that an edit of `kind` changed the state from `before` (call after applying it, only if it changed
    /// something).
    pub fn record(&mut self, kind: &'static str, before: Snapshot) {
        let now = Instant::now();
        let merge = matches!(self.last, Some((k, t)) if k == kind && now.duration_since(t) < self.coalesce)
            && !self.undo.is_empty();
        if !merge {
            self.undo.push(before);
            if self.undo.len() > self.limit {
                self.undo.remove(0);
            }
        }
        self.redo.clear();
        self.last = Some((kind, now));
    }

    /// The state to go back to, given the current one (which becomes redoable).
    pub fn undo(&mut self, current: Snapshot) -> Option<Snapshot> {
        let s = self.undo.pop()?;
        self.redo.push(current);
        self.last = None;
        Some(s)
    }

    /// The state to go forward to, given the current one (which becomes undoable).
    pub fn redo(&mut self, current: Snapshot) -> Option<Snapshot> {
        let s = self.redo.pop()?;
        self.undo.push(current);
        self.last = None;
        Some(s)
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }

    /// Forget everything (a new or opened session).
    pub fn clear(&mut self) {
        *self = Self {
            coalesce: self.coalesce,
            limit: self.limit,
            ..Self::default()
        };
    }
}
