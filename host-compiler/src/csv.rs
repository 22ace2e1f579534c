//! The one CSV dialect of the tools' text files: `simulate`'s runs, `mtl`'s traces and the recordings
//! `synth --import` and `play` read ([`crate::robustness::mtl::Trace`], [`crate::trajectory::csv`]).
//!
//! A leading byte-order mark is ignored; blank lines and comment lines (`#` first, after optional
//! whitespace) are skipped wherever they are; the comment `# x0 = a, b, …` before the header names a
//! run's initial state; the first other line is the header; fields are separated by commas and trimmed;
//! quoting is not supported. The columns named [`STATUS`] (what `simulate` writes) and [`LOCATION`] (a
//! hybrid run's location names) hold text and are not signals: a trace reader skips their fields, and
//! the import of recordings reads [`LOCATION`] as names. Lines and character columns are 1-based, as
//! errors print them.

/// The name of `simulate`'s status column, whose fields readers skip.
pub const STATUS: &str = "status";
/// The name of the column that gives each row's location of a hybrid plant by name (`simulate`, `play`;
/// read by [`crate::trajectory::csv`]).
pub const LOCATION: &str = "location";
/// The columns that hold text, not signals: [`STATUS`] and [`LOCATION`].
pub const TEXT_COLUMNS: [&str; 2] = [STATUS, LOCATION];

/// The text without a leading byte-order mark.
pub fn strip_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// Whether a line is skipped: blank, or a comment.
fn skipped(line: &str) -> bool {
    let t = line.trim_start();
    t.is_empty() || t.starts_with('#')
}

/// The lines that carry data (the header first), with their 1-based line numbers: the byte-order mark,
/// blank lines and comment lines left out.
pub fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    strip_bom(text)
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .filter(|(_, l)| !skipped(l))
}

/// The `# x0 …` comment before the header, if there is one: its line number and the text after `x0`
/// (for the caller to parse, e.g. `= 0.1, 0`).
pub fn x0_comment(text: &str) -> Option<(usize, &str)> {
    for (i, line) in strip_bom(text).lines().enumerate() {
        let t = line.trim();
        if let Some(rest) = t
            .strip_prefix('#')
            .map(str::trim_start)
            .and_then(|r| r.strip_prefix("x0"))
        {
            return Some((i + 1, rest));
        }
        if !skipped(line) {
            return None;
        }
    }
    None
}

/// The fields of a line, trimmed, each with the 1-based character column where it starts (after its
/// leading whitespace). Linear in the line's length.
pub fn split(row: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    // Characters before the current piece, counted as we go.
    let mut before = 0usize;
    for piece in row.split(',') {
        let trimmed = piece.trim_start();
        let lead = piece[..piece.len() - trimmed.len()].chars().count();
        out.push((before + lead + 1, piece.trim()));
        before += piece.chars().count() + 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bom_comments_and_blank_lines_are_skipped() {
        let text = "\u{feff}# x0 = 1, 2\n\n  # note\nt,a\n0,1\n# mid\n\n1,2\n";
        let lines: Vec<(usize, &str)> = data_lines(text).collect();
        assert_eq!(lines, vec![(4, "t,a"), (5, "0,1"), (8, "1,2")]);
        assert_eq!(x0_comment(text), Some((1, " = 1, 2")));
        // Only before the header.
        assert_eq!(x0_comment("t,a\n# x0 = 1\n0,1\n"), None);
        assert_eq!(x0_comment("\u{feff}#x0=3\nt\n"), Some((1, "=3")));
    }

    #[test]
    fn fields_are_trimmed_with_their_columns() {
        assert_eq!(split(" a, bb ,c"), vec![(2, "a"), (5, "bb"), (9, "c")]);
        assert_eq!(split("é,x"), vec![(1, "é"), (3, "x")]);
    }
}
