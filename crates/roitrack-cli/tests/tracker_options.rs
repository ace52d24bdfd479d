//! The tracker's options are defined once, in the library's table (`roitrack::estimators::tracker_options!`): every entry
//! is an option of `roitrack track` with the entry's help and default, and no other option reads as a tracker
//! option. (The Python side is checked by crates/roitrack-python/tests/test_options.py.)

mod common;
use common::{fails, ok};

/// One entry of the table: name, shape, default as written, help lines.
struct Entry {
    name: &'static str,
    shape: &'static str,
    default: &'static str,
    doc: Vec<&'static str>,
}

macro_rules! entries {
    ($($(#[doc = $doc:literal])* $name:ident : $shape:ident $ty:ty = $default:tt $(, $check:ident ($($arg:expr),*))?;)*) => {
        vec![$(Entry {
            name: stringify!($name),
            shape: stringify!($shape),
            default: stringify!($default),
            doc: vec![$($doc),*],
        }),*]
    };
}

/// The option a line of `--help` introduces (`      --every <EVERY>`: `--every`), if it is an option's first line.
fn option_of(line: &str) -> Option<&str> {
    let trimmed = line.trim_start();
    if !trimmed.starts_with('-') || line.len() - trimmed.len() > 6 {
        return None;
    }
    trimmed
        .split_whitespace()
        .find(|w| w.starts_with("--"))
        .map(|w| w.trim_end_matches(','))
}

/// `--help`'s text of `--option`: its lines up to the next option, joined by single spaces.
fn help_of(help: &str, option: &str) -> Option<String> {
    let mut lines = help
        .lines()
        .skip_while(|line| option_of(line) != Some(option));
    lines.next()?;
    let text: Vec<&str> = lines
        .take_while(|line| option_of(line).is_none())
        .map(str::trim)
        .filter(|line| !line.is_empty())
        .collect();
    Some(text.join(" "))
}

#[test]
fn every_option_of_the_table_is_an_option_of_track_with_its_help_and_default() {
    let table = roitrack::estimators::tracker_options!(entries);
    assert!(table.len() >= 14, "the table lists the tracker's options");
    let help = ok(&["track", "--help"]);
    for entry in &table {
        let option = format!("--{}", entry.name.replace('_', "-"));
        let text = help_of(&help, &option).unwrap_or_else(|| {
            panic!(
                "{option} (table entry {}) is not in `track --help`",
                entry.name
            )
        });
        let doc = entry
            .doc
            .iter()
            .map(|line| line.trim())
            .collect::<Vec<_>>()
            .join(" ");
        let summary = doc.strip_suffix('.').unwrap_or(&doc);
        assert!(
            text.starts_with(summary),
            "{option}: help {text:?} is not the table's {summary:?}"
        );
        let shown = text
            .split("[default: ")
            .nth(1)
            .and_then(|rest| rest.split(']').next());
        match (entry.shape, shown) {
            ("optional_number" | "optional_named", None) => assert_eq!(entry.default, "None"),
            ("number", Some(shown)) => assert_eq!(
                shown.parse::<f64>().ok(),
                entry.default.parse::<f64>().ok(),
                "{option}: default"
            ),
            ("named", Some(shown)) => {
                assert_eq!(shown, entry.default.trim_matches('"'), "{option}: default")
            }
            (shape, shown) => panic!("{option}: shape {shape} with default shown as {shown:?}"),
        }
    }
}

#[test]
fn named_options_take_the_library_names_and_numbers_their_range() {
    let table = roitrack::estimators::tracker_options!(entries);
    for entry in &table {
        let option = format!("--{}", entry.name.replace('_', "-"));
        let refused = fails(&["track", &option, "not-a-value"]);
        assert!(
            refused.contains(&format!("invalid value 'not-a-value' for '{option} <")),
            "{option}: {refused}"
        );
        if entry.shape.ends_with("named") {
            assert!(
                refused.contains("[possible values: "),
                "{option}: {refused}"
            );
        }
    }
}
