//! The record of pages that could not be read: each fault logged once, with what is done
//! without the page, and listed for the viewer's panel and the headless summary.

use super::PageError;
use std::sync::Mutex;

/// Page faults met while reading paged data, each once.
#[derive(Debug, Default)]
pub struct PageFaults {
    seen: Mutex<Vec<String>>,
}

impl PageFaults {
    /// Records `e` (logged the first time it is seen, with what is done without it).
    pub fn record(&self, e: &PageError) {
        self.record_as(e, "the bounds that read it are taken as unbounded there");
    }

    /// [`Self::record`] with the `consequence` the log names.
    pub fn record_as(&self, e: &PageError, consequence: &str) {
        let text = e.to_string();
        let mut seen = self
            .seen
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if !seen.contains(&text) {
            log::error!("{text}; {consequence}");
            seen.push(text);
        }
    }

    /// The faults seen so far, in order.
    pub fn list(&self) -> Vec<String> {
        self.seen
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }
}
