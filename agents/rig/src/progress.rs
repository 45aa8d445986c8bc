//! Progress bars on stderr for long jobs (hidden when stderr is not a terminal).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar over `total` steps with a label.
pub fn bar(total: u64, label: &str) -> ProgressBar {
    let pb = ProgressBar::new(total);
    let style = ProgressStyle::with_template("{msg:40} [{bar:30}] {pos}/{len} ({eta})")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    pb.set_style(style);
    pb.set_message(label.to_string());
    pb
}

/// A callback for multi-stage jobs: each (stage, done, total) updates one bar.
pub fn stages() -> (ProgressBar, impl FnMut(&str, u64, u64)) {
    let pb = bar(1, "");
    let handle = pb.clone();
    let f = move |stage: &str, done: u64, total: u64| {
        handle.set_length(total.max(1));
        handle.set_position(done);
        handle.set_message(stage.to_string());
    };
    (pb, f)
}
