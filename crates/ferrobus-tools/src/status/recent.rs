//! The recent warnings of a command, for its status page: the last [`Recent::KEEP`] lines, each
//! with when it was logged. The command's log hands them in ([`Recent::push`]).

use std::collections::VecDeque;
use std::sync::{Mutex, PoisonError};
use std::time::SystemTime;

use serde_json::{Value, json};

use crate::poll::iso8601_ms;

/// The recent warnings of this process.
pub static RECENT: Recent = Recent::new();

/// The last warnings logged, oldest first.
#[derive(Debug)]
pub struct Recent {
    lines: Mutex<VecDeque<(SystemTime, String)>>,
}

impl Recent {
    /// How many are kept.
    pub const KEEP: usize = 20;

    pub(crate) const fn new() -> Self {
        Recent { lines: Mutex::new(VecDeque::new()) }
    }

    /// Keeps `line`, logged now (the oldest goes past [`Recent::KEEP`]).
    pub fn push(&self, line: String) {
        let mut lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        if lines.len() == Recent::KEEP {
            lines.pop_front();
        }
        lines.push_back((SystemTime::now(), line));
    }

    /// Each kept line with its time, newest first, as the page takes them.
    pub fn list(&self) -> Vec<Value> {
        let lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        lines.iter().rev().map(|(at, line)| json!({"at": iso8601_ms(*at), "text": line})).collect()
    }
}
