//! Every option that takes a value says in `--help` what happens when it is not given: clap's `[default: ...]`, a
//! "Default: ..." sentence (for a computed default: the value and how it is derived), or it is required (shown
//! without brackets in the usage line).

mod common;
use common::{fails, ok};

/// The subcommands listed by `roitrack [COMMAND...] --help`.
fn subcommands(command: &[&str]) -> Vec<String> {
    let help = ok(&[command, &["--help"]].concat());
    let mut names = Vec::new();
    let mut inside = false;
    for line in help.lines() {
        if line.starts_with("Commands:") {
            inside = true;
            continue;
        }
        if inside {
            if line.trim().is_empty() || !line.starts_with("  ") {
                break;
            }
            let name = line.split_whitespace().next().unwrap_or("");
            if name != "help" {
                names.push(name.to_string());
            }
        }
    }
    names
}

/// (option, its help text) for each value-taking option of a help page, and the usage line.
fn options(help: &str) -> (String, Vec<(String, String)>) {
    let usage = help
        .lines()
        .find(|l| l.starts_with("Usage:"))
        .unwrap_or("")
        .to_string();
    let mut found: Vec<(String, String)> = Vec::new();
    for line in help.lines() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        let option = trimmed
            .strip_prefix("-")
            .and_then(|_| trimmed.split_whitespace().find(|w| w.starts_with("--")));
        match option {
            Some(name) if indent <= 6 => {
                let name = name.trim_end_matches(',').to_string();
                found.push((name, trimmed.to_string()));
            }
            _ => {
                if let Some(last) = found.last_mut() {
                    last.1.push(' ');
                    last.1.push_str(trimmed);
                }
            }
        }
    }
    let takes_value = |text: &str| {
        text.split_whitespace()
            .nth(1)
            .is_some_and(|w| w.starts_with('<'))
            || text
                .split_whitespace()
                .nth(2)
                .is_some_and(|w| w.starts_with('<'))
    };
    let found = found
        .into_iter()
        .filter(|(name, text)| name != "--help" && name != "--version" && takes_value(text))
        .collect();
    (usage, found)
}

/// Every command, and the subcommands of a command that has them (`target grid`; `lab compare` with the feature
/// `lab`).
fn commands() -> Vec<Vec<String>> {
    let mut commands = Vec::new();
    for command in subcommands(&[]) {
        commands.extend(
            subcommands(&[&command])
                .into_iter()
                .map(|sub| vec![command.clone(), sub]),
        );
        commands.push(vec![command]);
    }
    commands
}

#[test]
fn every_option_says_its_default_or_is_required() {
    let mut missing = Vec::new();
    let commands = commands();
    assert!(commands.len() >= 8, "{commands:?}");
    for command in &commands {
        let command: Vec<&str> = command.iter().map(String::as_str).collect();
        let help = ok(&[&command[..], &["--help"]].concat());
        let (usage, options) = options(&help);
        for (name, text) in options {
            let required =
                usage.contains(&format!(" {name} <")) && !usage.contains(&format!("[{name} <"));
            let said = text.contains("[default:") || text.to_lowercase().contains("default:");
            if !(required || said) {
                missing.push(format!("roitrack {} {name}", command.join(" ")));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "options whose --help says neither a default nor that they are required:\n{}",
        missing.join("\n")
    );
}

#[test]
fn an_unknown_option_points_to_help() {
    let err = fails(&["track", "--noise", "0.2"]);
    assert!(err.contains("--noise") && err.contains("--help"), "{err}");
}
