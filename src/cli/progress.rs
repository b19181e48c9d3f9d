//! Progress for every long command: a bar on a terminal, a log line every `--progress-interval`
//! seconds otherwise (nohup, CI, containers).

/// `--progress-interval`, set once in `main`.
pub(super) static PROGRESS_INTERVAL: std::sync::OnceLock<f64> = std::sync::OnceLock::new();

/// One progress log line: "what: pos/len (pct), rate, eta".
///
/// The rate is the average since the first logged tick (`since_first`: seconds and items), or,
/// before there is one or while no item finished since, since the bar was made
/// (`since_start` seconds, `pos` items). A resumed run's bar jumps to its start position,
/// which an average since creation would count as done at once; the tick-based average does
/// not. indicatif's own rate is a short moving window that decays to 0/s between items that
/// take longer than the window (guided samples: ~20 s each), which made the ETA meaningless.
/// Slow items print as "N s each" rather than "0.05/s".
pub(crate) fn progress_line(
    what: &str,
    pos: u64,
    len: u64,
    since_start: f64,
    since_first: Option<(f64, u64)>,
) -> String {
    let pct = 100.0 * pos as f64 / len.max(1) as f64;
    let (secs, done) = match since_first {
        Some((s, d)) if d > 0 && s > 0.0 => (s, d),
        _ => (since_start, pos),
    };
    if done == 0 || secs <= 0.0 {
        return format!("{what}: {pos}/{len} ({pct:.1}%), eta unknown");
    }
    let rate = done as f64 / secs;
    let speed = if rate >= 1.0 {
        format!("{rate:.2}/s")
    } else {
        format!("{:.1} s each", 1.0 / rate)
    };
    let eta = len.saturating_sub(pos) as f64 / rate;
    format!("{what}: {pos}/{len} ({pct:.1}%), {speed}, eta {eta:.0}s")
}

/// A progress bar on stderr. indicatif hides it when stderr is not a terminal; then a watcher
/// thread logs "what: pos/len, rate, eta" every `--progress-interval` seconds instead, so a long
/// run under nohup, CI or docker still shows that it moves. The watcher holds only a weak
/// reference and stops when the bar is finished or dropped.
pub(crate) fn progress_bar(total: usize, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(total as u64);
    let every = PROGRESS_INTERVAL.get().copied().unwrap_or(30.0);
    if pb.is_hidden() && every > 0.0 {
        let weak = pb.downgrade();
        let what = what.to_string();
        let spawned = std::thread::Builder::new()
            .name("progress-log".into())
            .spawn(move || {
                let started = std::time::Instant::now();
                let mut first: Option<(std::time::Instant, u64)> = None;
                loop {
                    std::thread::sleep(std::time::Duration::from_secs_f64(every));
                    let Some(pb) = weak.upgrade() else { break };
                    if pb.is_finished() {
                        break;
                    }
                    let (pos, len) = (pb.position(), pb.length().unwrap_or(0));
                    let since_first =
                        first.map(|(t, p)| (t.elapsed().as_secs_f64(), pos.saturating_sub(p)));
                    first.get_or_insert((std::time::Instant::now(), pos));
                    tracing::info!(
                        "{}",
                        progress_line(
                            &what,
                            pos,
                            len,
                            started.elapsed().as_secs_f64(),
                            since_first
                        )
                    );
                }
            });
        if let Err(e) = spawned {
            tracing::warn!("no progress logging: {e}");
        }
    }
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:>10} [{bar:40}] {pos}/{len} {per_sec} eta {eta} {prefix}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

#[cfg(test)]
mod tests {
    use super::progress_line;

    #[test]
    fn progress_line_rate_and_eta_for_slow_and_fast_items() {
        // Before anything finished there is no rate to extrapolate.
        assert_eq!(
            progress_line("sample", 0, 300, 30.0, None),
            "sample: 0/300 (0.0%), eta unknown"
        );
        // Slow items (20 s each): seconds per item, and the ETA of the remaining 290.
        assert_eq!(
            progress_line("sample", 10, 300, 200.0, Some((160.0, 8))),
            "sample: 10/300 (3.3%), 20.0 s each, eta 5800s"
        );
        // No item finished since the first tick: fall back to the average since the start.
        assert_eq!(
            progress_line("sample", 2, 300, 40.0, Some((10.0, 0))),
            "sample: 2/300 (0.7%), 20.0 s each, eta 5960s"
        );
        // A resumed run jumps to step 5000; the rate counts only steps done since.
        assert_eq!(
            progress_line("shape", 5090, 12000, 60.0, Some((30.0, 90))),
            "shape: 5090/12000 (42.4%), 3.00/s, eta 2303s"
        );
    }
}
