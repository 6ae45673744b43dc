//! Progress bars (kdam) for long CLI work: drawn on stderr when it is a terminal, never with `--quiet` or when
//! stderr goes to a file or pipe (logs stay free of bar redraws). The result lines on stdout are unaffected.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};

static QUIET: AtomicBool = AtomicBool::new(false);

/// Set by `tnd --quiet` before any command runs.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

fn hidden() -> bool {
    QUIET.load(Ordering::Relaxed) || !std::io::stderr().is_terminal()
}

/// A bar with `desc` counting `unit`s up to `total` (0: set later), hidden where it should not draw.
pub fn bar(desc: &str, unit: &str, total: usize) -> kdam::Bar {
    kdam::Bar::builder()
        .desc(desc)
        .unit(unit)
        .total(total)
        .mininterval(0.2)
        .disable(hidden())
        .build()
        .unwrap_or_else(|_| {
            // The builder refuses only inconsistent settings, which these are not; draw nothing if it ever does.
            let mut b = kdam::Bar::default();
            b.disable = true;
            b
        })
}

/// Draw a bar's final state and end its line (nothing when hidden).
pub fn finish(bar: &mut kdam::Bar) {
    use kdam::BarExt;
    if !bar.disable {
        let _ = bar.refresh();
        eprintln!();
    }
}

/// A progress callback for the library's use cases ([`tactile_derender::pipeline::Progress`]) drawing `bar`: it sets
/// the total it is told and never cancels.
pub fn callback(bar: &mut kdam::Bar) -> impl FnMut(usize, usize) -> bool + '_ {
    use kdam::BarExt;
    move |done, total| {
        bar.total = total;
        let _ = bar.update_to(done);
        true
    }
}
