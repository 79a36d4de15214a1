//! One module per `tangent` subcommand. Each exposes an `Args` struct (clap) and
//! `run(args) -> anyhow::Result<ExitCode>`.
//!
//! Errors: every error about a file names the file and its cause, once. The library's errors
//! name the files they were given (`calibration_file`, `pgm`, `fieldlog`) or, for a capture,
//! the files inside it, after which the command puts the capture directory; a command adds
//! context only where the library's message does not already name the path.

pub mod accuracy;
pub mod app;
pub mod calibrate;
pub mod device_calibration;
pub mod devices;
pub mod evaluate;
pub mod flash;
pub mod inspect;
pub mod listen;
pub mod log;
pub mod measure;
pub mod record;
pub mod simulate;
pub mod study;

/// The message of `err` with its causes, `context: cause: cause…`, leaving out a cause that
/// an earlier message already contains (several error types put their I/O cause both in
/// their message and in `source()`; `anyhow`'s `{:#}` would print it twice).
pub fn error_text(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::error_text;

    #[derive(Debug, thiserror::Error)]
    #[error("{path}: {source}")]
    struct Both {
        path: String,
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_printed_once() {
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let err = anyhow::Error::new(Both {
            path: "a.log".into(),
            source: io(),
        })
        .context("cannot open the field log");
        assert_eq!(error_text(&err), "cannot open the field log: a.log: gone");
        let err = anyhow::Error::new(io()).context("writing out.png");
        assert_eq!(error_text(&err), "writing out.png: gone");
    }
}
