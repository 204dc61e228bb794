//! Resuming a run: its saved settings and model read back (a setting it was saved without at
//! its default), and what a resumed run may not change.

use super::{TrainSettings, CONFIG_FILE, SETTINGS_FILE};
use crate::model::ModelConfig;
use serde_json::Value;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Settings a resumed run may change: they decide how the run is carried out and reported, not
/// what it computes (the training samples scored beside the validation decide nothing).
const OPERATIONAL: [&str; 3] = ["log_every", "keep", "seen_samples"];

#[derive(Debug, Error)]
pub enum ResumeError {
    #[error("{}: cannot resume without it: {source}", path.display())]
    Missing {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: unreadable: {source}", path.display())]
    Unreadable {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("{}: a resumed run keeps its {what} ({difference})", run.display())]
    Changed {
        run: PathBuf,
        what: &'static str,
        difference: String,
    },
}

/// The settings and model config the run in `run` was started with.
pub fn saved(run: &Path) -> Result<(TrainSettings, ModelConfig), ResumeError> {
    let path = run.join(SETTINGS_FILE);
    let mut settings: Value = read(&path)?;
    let defaults = serde_json::to_value(TrainSettings::default()).unwrap_or_default();
    fill_missing(&mut settings, &defaults);
    let settings = serde_json::from_value(settings)
        .map_err(|source| ResumeError::Unreadable { path, source })?;
    Ok((settings, read(&run.join(CONFIG_FILE))?))
}

/// Refuses settings or a model that differ from the saved ones, naming the first difference
/// down to its innermost field (`loss.style: the run has 250.0, the options give 1.0`).
pub fn check_unchanged(
    run: &Path,
    saved: &(TrainSettings, ModelConfig),
    settings: &TrainSettings,
    model: &ModelConfig,
) -> Result<(), ResumeError> {
    let changed = |what, difference| ResumeError::Changed {
        run: run.to_path_buf(),
        what,
        difference,
    };
    if let Some(diff) = first_difference(&saved.0, settings, &OPERATIONAL) {
        return Err(changed("settings", diff));
    }
    if let Some(diff) = first_difference(&saved.1, model, &[]) {
        return Err(changed("model", diff));
    }
    Ok(())
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, ResumeError> {
    let text = std::fs::read_to_string(path).map_err(|source| ResumeError::Missing {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|source| ResumeError::Unreadable {
        path: path.to_path_buf(),
        source,
    })
}

/// Adds the fields `saved` lacks at their `defaults`: a run started before a setting existed
/// ran as its default (the depth term's weight, for one, was 0 before it could be set).
fn fill_missing(saved: &mut Value, defaults: &Value) {
    let (Value::Object(saved), Value::Object(defaults)) = (saved, defaults) else {
        return;
    };
    for (key, default) in defaults {
        match saved.get_mut(key) {
            Some(value) => fill_missing(value, default),
            None => {
                saved.insert(key.clone(), default.clone());
            }
        }
    }
}

/// The first field of `new` that differs from `saved`, ignoring `except`, named down to the
/// innermost field (`loss.style`).
fn first_difference<T: serde::Serialize>(saved: &T, new: &T, except: &[&str]) -> Option<String> {
    let (Ok(a), Ok(b)) = (serde_json::to_value(saved), serde_json::to_value(new)) else {
        return None;
    };
    differing_field(&a, &b, except, "")
}

fn differing_field(a: &Value, b: &Value, except: &[&str], path: &str) -> Option<String> {
    let (Value::Object(a), Value::Object(b)) = (a, b) else {
        return (a != b).then(|| format!("{path}: the run has {a}, the options give {b}"));
    };
    a.iter()
        .filter(|(k, _)| !except.contains(&k.as_str()))
        .find_map(|(k, v)| {
            let inner = if path.is_empty() {
                k.clone()
            } else {
                format!("{path}.{k}")
            };
            differing_field(v, b.get(k).unwrap_or(&Value::Null), &[], &inner)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_difference_is_named_down_to_its_field() {
        let saved = TrainSettings::default();
        let mut new = saved.clone();
        new.loss.style = 1.0;
        let diff = first_difference(&saved, &new, &[]).unwrap();
        assert!(diff.starts_with("loss.style: the run has 250"), "{diff}");
        new = saved.clone();
        new.keep += 1;
        assert_eq!(first_difference(&saved, &new, &OPERATIONAL), None);
    }

    #[test]
    fn settings_saved_before_a_field_existed_get_its_default() {
        let mut saved = serde_json::json!({ "loss": { "style": 1.0 } });
        let defaults = serde_json::json!({ "loss": { "style": 250.0, "depth": 0.0 }, "keep": 3 });
        fill_missing(&mut saved, &defaults);
        let expected = serde_json::json!({ "loss": { "style": 1.0, "depth": 0.0 }, "keep": 3 });
        assert_eq!(saved, expected);
    }
}
