//! Progress bars on stderr (indicatif): hidden with `--quiet` and when stderr is not a terminal.

use std::path::Path;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

fn styled(quiet: bool, len: u64, template: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// A bar of `len` steps labelled `prefix`; hidden when `quiet`.
pub fn bar(quiet: bool, len: u64, prefix: &str) -> ProgressBar {
    let pb = styled(
        quiet,
        len,
        "{prefix:>12} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}",
    );
    pb.set_prefix(prefix.to_owned());
    pb
}

/// A bar of the bytes of `file` read; hidden when `quiet`.
pub fn bytes(quiet: bool, total: u64, file: &Path) -> ProgressBar {
    let pb = styled(
        quiet,
        total,
        "{msg} [{bar:40}] {bytes}/{total_bytes} ({eta})",
    );
    pb.set_message(format!("reading {}", file.display()));
    pb
}
