//! The reference pages that are generated from, or checked against, the code, so that they
//! cannot drift: `docs/cli.md` (every command's `--help`, rendered by clap) and the options
//! table of `docs/options.md` (every `hbn train` flag, its Python keyword, its Rust field and
//! its default).
//!
//! Regenerate `docs/cli.md` after changing a flag or its help:
//!
//! ```text
//! HBN_UPDATE_DOCS=1 cargo test --release --test docs_reference
//! ```

use clap::CommandFactory;
use hbn::model::Param;
use hbn_cli::cli::Cli;
use std::path::PathBuf;

fn repo_file(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// `docs/cli.md` as clap renders it: each subcommand's long help, at a fixed width.
fn cli_reference() -> String {
    let mut root = Cli::command().term_width(100).max_term_width(100);
    root.build();
    let mut out = String::from(
        "# The `hbn` command line\n\n\
         Generated from the CLI's own help by `tests/docs_reference.rs` \
         (`HBN_UPDATE_DOCS=1 cargo test --release --test docs_reference`); \
         `hbn <command> --help` prints the same. Every training option with its Python keyword \
         and Rust field: [options.md](options.md).\n\n",
    );
    out.push_str("```text\n");
    out.push_str(&root.render_long_help().to_string());
    out.push_str("```\n");
    for sub in root.get_subcommands() {
        let name = sub.get_name();
        if name == "help" {
            continue;
        }
        let mut sub = sub.clone().bin_name(format!("hbn {name}"));
        out.push_str(&format!("\n## hbn {name}\n\n```text\n"));
        out.push_str(&sub.render_long_help().to_string());
        out.push_str("```\n");
    }
    // No trailing spaces (clap pads blank lines of long help).
    out.lines()
        .map(str::trim_end)
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

#[test]
fn the_cli_reference_is_the_clis_help() {
    let path = repo_file("docs/cli.md");
    let fresh = cli_reference();
    if std::env::var_os("HBN_UPDATE_DOCS").is_some() {
        std::fs::write(&path, &fresh).unwrap();
        return;
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "docs/cli.md differs from the CLI's help: regenerate it with \
         `HBN_UPDATE_DOCS=1 cargo test --release --test docs_reference`"
    );
}

/// One row of the options table.
#[derive(Debug)]
struct Row {
    flag: String,
    python: Option<String>,
    rust: Option<String>,
    /// The default in backticks (`None`: described in words).
    default: Option<String>,
}

fn code(cell: &str) -> Option<String> {
    let c = cell.trim();
    (c.len() >= 2 && c.starts_with('`') && c.ends_with('`') && c.matches('`').count() == 2)
        .then(|| c[1..c.len() - 1].to_owned())
}

fn options_table() -> Vec<Row> {
    let text = std::fs::read_to_string(repo_file("docs/options.md")).unwrap();
    let begin = text
        .find("<!-- options-table: begin -->")
        .expect("docs/options.md has no options-table begin marker");
    let end = text
        .find("<!-- options-table: end -->")
        .expect("docs/options.md has no options-table end marker");
    text[begin..end]
        .lines()
        .filter(|l| l.starts_with('|'))
        .skip(2) // header and rule
        .map(|l| {
            let cells: Vec<&str> = l.trim().trim_matches('|').split('|').collect();
            assert_eq!(
                cells.len(),
                5,
                "options table row with other than 5 cells: {l}"
            );
            Row {
                flag: code(cells[1]).unwrap_or_else(|| panic!("no `--flag` in row {l}")),
                python: code(cells[2]),
                rust: code(cells[3]),
                default: code(cells[4]),
            }
        })
        .collect()
}

#[test]
fn the_options_table_lists_every_train_flag_with_its_default() {
    let rows = options_table();
    let mut root = Cli::command();
    root.build();
    let train = root
        .find_subcommand("train")
        .expect("hbn train exists")
        .clone();
    let mut listed = Vec::new();
    for arg in train.get_arguments() {
        let Some(long) = arg.get_long() else { continue };
        if matches!(long, "help" | "version" | "quiet" | "verbose") {
            continue;
        }
        let flag = format!("--{long}");
        let row = rows
            .iter()
            .find(|r| r.flag == flag)
            .unwrap_or_else(|| panic!("docs/options.md does not list `hbn train {flag}`"));
        let clap_default: Vec<String> = arg
            .get_default_values()
            .iter()
            .map(|v| v.to_string_lossy().into_owned())
            .collect();
        let is_switch = matches!(arg.get_action(), clap::ArgAction::SetTrue);
        match &row.default {
            Some(d) => assert_eq!(
                d,
                &clap_default.join(","),
                "docs/options.md gives `{flag}` the default `{d}`, `hbn train --help` another"
            ),
            None => assert!(
                clap_default.is_empty() || is_switch,
                "docs/options.md describes the default of `{flag}` in words, but clap has \
                 `{}`: put it in backticks",
                clap_default.join(",")
            ),
        }
        listed.push(flag);
    }
    for row in &rows {
        assert!(
            listed.contains(&row.flag),
            "docs/options.md lists `{}`, which `hbn train` does not have",
            row.flag
        );
    }
    // Every training parameter a front end can set is in the table, under its Rust name,
    // and Python's keyword is that name (one name per concept).
    for param in hbn::model::Param::ALL {
        if param == Param::Blr {
            continue; // the local regression's prior is set in Rust only
        }
        let name = param.name();
        let row = rows
            .iter()
            .find(|r| r.python.as_deref() == Some(name))
            .unwrap_or_else(|| {
                panic!("docs/options.md has no row with the Python keyword `{name}`")
            });
        let rust = row.rust.as_deref().unwrap_or("—");
        let expected = format!("HbnParams::{name}");
        let ok = match param {
            // Both kernels at once: the front ends' shorthand for the two fields.
            Param::Kernel => rust.starts_with("HbnParams::"),
            // The grid rate is a reading option that the model keeps as its rate.
            Param::Rate => rust == expected || rust == "LogOptions::rate_hz",
            _ => rust == expected,
        };
        assert!(
            ok,
            "the Rust cell of `{}` is `{rust}`, not `{expected}`",
            row.flag
        );
    }
}
