//! What a training run says as it goes and at its end: each log record's line for a person,
//! the closing lines, and the typed report `train --json` prints.

use super::validate::Scores;
use super::{LogRecord, Outcome, Summary};
use serde::Serialize;
use std::path::{Path, PathBuf};

fn cd_text(cd: Option<f64>) -> String {
    cd.map_or("- (empty output)".to_string(), |c| format!("{c:.3e}"))
}

impl LogRecord {
    /// The line a person is shown for this record; none for the periodic loss averages, which
    /// the progress bar shows.
    pub fn said(&self) -> Option<String> {
        match self {
            LogRecord::Train { .. } => None,
            LogRecord::Validation {
                step, scores, seen, ..
            } => Some(format!(
                "step {step}: validation CD {} F1@0.01 {:.3} (P {:.3} R {:.3}), geometry PSNR \
                 {:.2} dB SSIM {:.3}{}{}",
                cd_text(scores.cd),
                scores.f1,
                scores.precision,
                scores.recall,
                scores.geometry.psnr,
                scores.geometry.ssim,
                scores
                    .color
                    .map_or(String::new(), |c| format!(", colour PSNR {:.2} dB", c.psnr)),
                seen.as_ref().map_or(String::new(), |s| format!(
                    "; training samples CD {} F1@0.01 {:.3}",
                    cd_text(s.cd),
                    s.f1
                )),
            )),
            LogRecord::Baseline { scores } => Some(format!(
                "partial inputs of the {} validation samples: CD {} F1@0.01 {:.3}",
                scores.samples,
                scores.cd.map_or("-".to_string(), |c| format!("{c:.3e}")),
                scores.f1
            )),
        }
    }
}

/// What `train --json` prints.
#[derive(Debug, Serialize)]
pub struct TrainReport<'a> {
    pub run: &'a Path,
    pub outcome: Outcome,
    pub step: u64,
    /// Counted from 1.
    pub stage: usize,
    pub checkpoint: &'a Path,
    pub best_cd: Option<f64>,
    pub best_step: Option<u64>,
    pub baseline: Option<&'a Scores>,
    pub validation: Option<&'a Scores>,
    pub seen: Option<&'a Scores>,
}

impl Summary {
    /// The report of the run in `run`.
    pub fn report<'a>(&'a self, run: &'a Path) -> TrainReport<'a> {
        TrainReport {
            run,
            outcome: self.outcome,
            step: self.state.step,
            stage: self.state.stage + 1,
            checkpoint: &self.checkpoint,
            best_cd: self.state.best_cd,
            best_step: self.state.best_step,
            baseline: self.baseline.as_ref(),
            validation: self.last.as_ref(),
            seen: self.last_seen.as_ref(),
        }
    }

    /// How the run ended and where its best validation is, for a person; `stages` is how many
    /// learning-rate stages it had.
    pub fn said(&self, stages: usize, run: &Path) -> Vec<String> {
        let (step, checkpoint) = (self.state.step, self.checkpoint.display());
        let mut lines = vec![match self.outcome {
            Outcome::Interrupted => format!(
                "interrupted at step {step}: checkpoint {checkpoint} (continue with --resume)"
            ),
            Outcome::StepLimit => {
                format!("stopped at step {step} (--steps): checkpoint {checkpoint}")
            }
            Outcome::Finished => {
                format!("all {stages} stages done at step {step}: checkpoint {checkpoint}")
            }
        }];
        if let (Some(cd), Some(best)) = (self.state.best_cd, self.state.best_step) {
            let best_dir: PathBuf = run.join("best");
            lines.push(format!(
                "best validation CD {cd:.3e} at step {best}: {}",
                best_dir.display()
            ));
        }
        lines
    }
}
