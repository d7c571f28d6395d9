//! Progress bars (indicatif) for long work, hidden when stderr is not a terminal.

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressStyle};

/// A progress reporter keyed by stage name: a new stage starts a new bar.
pub struct Stages {
    bar: Mutex<Option<(String, ProgressBar)>>,
}

impl Stages {
    pub fn new() -> Stages {
        Stages {
            bar: Mutex::new(None),
        }
    }

    pub fn report(&self, stage: &str, done: u64, total: u64) {
        let mut g = self.bar.lock().unwrap();
        if g.as_ref().is_none_or(|(s, _)| s != stage) {
            if let Some((_, b)) = g.take() {
                b.finish();
            }
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{prefix:>12} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
                )
                .unwrap()
                .progress_chars("=> "),
            );
            b.set_prefix(stage.to_string());
            *g = Some((stage.to_string(), b));
        }
        let (_, b) = g.as_ref().unwrap();
        b.set_length(total);
        b.set_position(done);
    }

    pub fn finish(&self) {
        if let Some((_, b)) = self.bar.lock().unwrap().take() {
            b.finish();
        }
    }
}
