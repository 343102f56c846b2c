//! Links from the output to `docs/glossary.md`, where every term the CLI prints is explained.
//! Output names a term through [`Term`], so a test can check that every link has its section.

/// The glossary, relative to the repository root.
pub const GLOSSARY: &str = "docs/glossary.md";

/// A section of the glossary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Term {
    /// Signal names and paths.
    Signals,
    /// Grid samples, and why `estimate` and `eval` may count differently.
    Samples,
    /// Training rows per GP.
    Rows,
    /// The estimation modes.
    Modes,
    /// The model's default mode.
    DefaultMode,
    /// The open-loop GP simulation.
    OpenLoop,
    /// RMSE and nRMSE.
    Nrmse,
    /// The share of samples within 2 standard deviations.
    Coverage,
    /// Normalised estimation error squared.
    Nees,
    /// Negative log predictive density.
    Nlpd,
    /// Normalised innovation squared.
    Nis,
    /// The filter's guard flags.
    GuardFlags,
    /// Observability (lambda_min, near-unobservable).
    Observability,
    /// Support points of exact GPs.
    SupportPoints,
    /// Inducing points of sparse GPs.
    InducingPoints,
    /// Length scales and the GP inputs they belong to.
    LengthScales,
    /// Log marginal likelihood.
    Lml,
    /// Optimiser starts and how they ended.
    OptimiserStarts,
    /// Jitter.
    Jitter,
    /// The BLR index.
    BlrIndex,
    /// The held-out validation table.
    ValidationTable,
    /// The simulator's noise gain.
    NoiseGain,
    /// `corr(q, x)` of the experiment table.
    NoiseStateCorrelation,
}

impl Term {
    /// Every term.
    pub const ALL: [Term; 23] = [
        Term::Signals,
        Term::Samples,
        Term::Rows,
        Term::Modes,
        Term::DefaultMode,
        Term::OpenLoop,
        Term::Nrmse,
        Term::Coverage,
        Term::Nees,
        Term::Nlpd,
        Term::Nis,
        Term::GuardFlags,
        Term::Observability,
        Term::SupportPoints,
        Term::InducingPoints,
        Term::LengthScales,
        Term::Lml,
        Term::OptimiserStarts,
        Term::Jitter,
        Term::BlrIndex,
        Term::ValidationTable,
        Term::NoiseGain,
        Term::NoiseStateCorrelation,
    ];

    /// The section's anchor in the glossary (GitHub's heading ids).
    pub const fn anchor(self) -> &'static str {
        match self {
            Term::Signals => "signals",
            Term::Samples => "samples",
            Term::Rows => "rows",
            Term::Modes => "modes",
            Term::DefaultMode => "default-mode",
            Term::OpenLoop => "open-loop",
            Term::Nrmse => "rmse-and-nrmse",
            Term::Coverage => "2-sigma-coverage",
            Term::Nees => "nees",
            Term::Nlpd => "nlpd",
            Term::Nis => "nis",
            Term::GuardFlags => "guard-flags",
            Term::Observability => "observability",
            Term::SupportPoints => "support-points",
            Term::InducingPoints => "inducing-points",
            Term::LengthScales => "length-scales",
            Term::Lml => "lml",
            Term::OptimiserStarts => "optimiser-starts",
            Term::Jitter => "jitter",
            Term::BlrIndex => "blr-index",
            Term::ValidationTable => "validation-table",
            Term::NoiseGain => "noise-gain",
            Term::NoiseStateCorrelation => "noise-state-correlation",
        }
    }

    /// `docs/glossary.md#anchor`.
    pub fn link(self) -> String {
        format!("{GLOSSARY}#{}", self.anchor())
    }
}

/// `terms: docs/glossary.md#a, #b, #c`: one line that links several terms.
pub fn links(terms: &[Term]) -> String {
    let mut s = format!("terms: {GLOSSARY}");
    for (i, t) in terms.iter().enumerate() {
        s.push_str(if i == 0 { "#" } else { ", #" });
        s.push_str(t.anchor());
    }
    s
}

/// The ids GitHub gives the `## ` and `### ` headings of a Markdown text: lower case, spaces
/// to `-`, punctuation other than `-` and `_` dropped.
pub fn heading_ids(markdown: &str) -> Vec<String> {
    markdown
        .lines()
        .filter_map(|l| {
            l.strip_prefix("### ")
                .or_else(|| l.strip_prefix("## "))
                .or_else(|| l.strip_prefix("# "))
        })
        .map(|h| {
            h.trim()
                .to_lowercase()
                .chars()
                .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
                .map(|c| if c == ' ' { '-' } else { c })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = include_str!("../../docs/glossary.md");

    /// Every link the output prints leads to a section of the glossary.
    #[test]
    fn every_term_has_a_section() {
        let ids = heading_ids(TEXT);
        for t in Term::ALL {
            assert!(
                ids.iter().any(|id| id == t.anchor()),
                "docs/glossary.md has no section #{} (sections: {ids:?})",
                t.anchor()
            );
        }
    }

    /// Every guard flag the filter can set is explained.
    #[test]
    fn every_flag_is_explained() {
        for name in hbn_core::Flags::NAMES {
            assert!(
                TEXT.contains(&format!("| `{name}` |")),
                "docs/glossary.md does not explain the flag `{name}`"
            );
        }
    }

    /// Every mode is explained (as its flag spells it).
    #[test]
    fn every_mode_is_explained() {
        for m in hbn_core::Mode::ALL {
            assert!(
                TEXT.contains(&format!("- `{}`: ", m.name())),
                "docs/glossary.md#modes does not explain the mode `{m}`"
            );
        }
    }

    #[test]
    fn links_and_ids() {
        assert_eq!(
            links(&[Term::Nis, Term::GuardFlags]),
            "terms: docs/glossary.md#nis, #guard-flags"
        );
        assert_eq!(
            heading_ids("## RMSE and nRMSE\n## 2-sigma coverage\n"),
            ["rmse-and-nrmse", "2-sigma-coverage"]
        );
    }
}
