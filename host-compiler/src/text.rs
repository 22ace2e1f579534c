//! Quoting user text in messages: an excerpt of bounded length, so that a huge line, field or header
//! (a row of a million columns) is never echoed whole into an error; and a source text as a diagnostic
//! shows it, each overlong line cut to an excerpt around what it points at (`clip_source`).

use std::ops::Range;

/// The most characters of user text a message quotes.
pub const MAX_EXCERPT: usize = 64;

/// `s` itself when it has at most [`MAX_EXCERPT`] characters; else its first ones, an ellipsis and
/// its length, e.g. `abcd… (1048576 characters)`.
pub fn excerpt(s: &str) -> String {
    match s.char_indices().nth(MAX_EXCERPT) {
        None => s.to_string(),
        Some((end, _)) => format!("{}… ({} characters)", &s[..end], s.chars().count()),
    }
}

/// `s` with every run of non-blank characters longer than [`MAX_EXCERPT`] cut to an excerpt: for a
/// message that quotes user text inside its own words (a parser's "invalid type: string \"…\"").
pub fn clip_runs(s: &str) -> String {
    let mut out = String::with_capacity(s.len().min(1 << 12));
    let mut run = String::new();
    let flush = |run: &mut String, out: &mut String| {
        out.push_str(&excerpt(run));
        run.clear();
    };
    for c in s.chars() {
        if c.is_whitespace() {
            flush(&mut run, &mut out);
            out.push(c);
        } else {
            run.push(c);
        }
    }
    flush(&mut run, &mut out);
    out
}

/// The longest source line a rendering shows whole; a longer one is cut to an excerpt of
/// [`MAX_EXCERPT`] characters around its first label.
pub const MAX_SHOWN_LINE: usize = 2 * MAX_EXCERPT;

/// The source as a diagnostic shows it: every line longer than [`MAX_SHOWN_LINE`] characters cut to
/// [`MAX_EXCERPT`] characters around the first label that starts in it (or its start), with
/// `…` and the line's length around the cut, so that a huge value is never echoed whole by a diagnostic
/// that renders its source (miette); and the spans moved to the same text in the result (a span
/// outside the kept window is pinned to its edge). Lines keep their numbers.
pub fn clip_source(text: &str, labels: &[Range<usize>]) -> (String, Vec<Range<usize>>) {
    let keep = MAX_EXCERPT;
    let mut out = String::with_capacity(text.len().min(1 << 16));
    // (start in text, end in text, start in out, kept start in text, kept end in text, prefix len)
    let mut pieces: Vec<(usize, usize, usize, usize, usize, usize)> = Vec::new();
    let mut start = 0;
    for line in text.split_inclusive('\n') {
        let end = start + line.len();
        let body = line.trim_end_matches(['\n', '\r']);
        let chars = body.chars().count();
        let out_start = out.len();
        if chars <= MAX_SHOWN_LINE {
            out.push_str(line);
            pieces.push((start, end, out_start, start, end, 0));
        } else {
            // The window: from a little before the first label in this line, `keep` characters long.
            let anchor = labels
                .iter()
                .map(|r| r.start)
                .filter(|&a| a >= start && a < start + body.len())
                .min()
                .unwrap_or(start)
                - start;
            let offsets: Vec<usize> = body.char_indices().map(|(i, _)| i).collect();
            let anchor_char = offsets.partition_point(|&o| o < anchor);
            let first = anchor_char
                .saturating_sub(keep / 4)
                .min(chars.saturating_sub(keep));
            let last = (first + keep).min(chars);
            let kept_lo = offsets[first];
            let kept_hi = offsets.get(last).copied().unwrap_or(body.len());
            let prefix = if first > 0 { "…" } else { "" };
            out.push_str(prefix);
            out.push_str(&body[kept_lo..kept_hi]);
            out.push_str(&format!("… ({chars} characters)"));
            out.push_str(&line[body.len()..]);
            pieces.push((
                start,
                end,
                out_start,
                start + kept_lo,
                start + kept_hi,
                prefix.len(),
            ));
        }
        start = end;
    }
    let map = |at: usize| -> usize {
        match pieces.iter().find(|p| at >= p.0 && at < p.1) {
            Some(&(_, _, o, klo, khi, pre)) => o + pre + (at.clamp(klo, khi) - klo),
            None => out.len(),
        }
    };
    let moved = labels
        .iter()
        .map(|r| {
            let s = map(r.start);
            let e = if r.end > r.start {
                map(r.end - 1).max(s) + 1
            } else {
                s
            };
            let e = e.min(out.len());
            let mut s = s.min(e);
            while !out.is_char_boundary(s) {
                s -= 1;
            }
            let mut e = e;
            while !out.is_char_boundary(e) {
                e += 1;
            }
            s..e
        })
        .collect();
    (out, moved)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_runs_in_a_message_are_cut_and_short_words_kept() {
        let m = format!(
            "invalid type: string \"{}\", expected f64",
            "a".repeat(10_000)
        );
        let c = clip_runs(&m);
        assert!(c.starts_with("invalid type: string \"aaaa"), "{c}");
        assert!(c.ends_with("(10003 characters) expected f64"), "{c}");
        assert!(c.len() < 200, "{c}");
        assert_eq!(clip_runs("a  b\nc"), "a  b\nc");
    }

    #[test]
    fn an_overlong_line_is_shown_as_an_excerpt_around_its_label() {
        let long = "x".repeat(1_000_000);
        let text = format!("a = 1\nf = [\"{long}\"]\nb = 2\n");
        let at = text.find("xxx").unwrap() + 500_000;
        let (shown, labels) = clip_source(&text, &[at..at + 3]);
        assert!(shown.len() < 400, "{} bytes shown", shown.len());
        assert!(shown.starts_with("a = 1\n…"), "{shown}");
        assert!(shown.ends_with("(1000008 characters)\nb = 2\n"), "{shown}");
        let r = &labels[0];
        assert_eq!(&shown[r.clone()], "xxx");
        // Short sources are shown as they are.
        let (same, l2) = clip_source("a = 1\n", &[0..1]);
        assert_eq!(same, "a = 1\n");
        assert_eq!(l2[0], 0..1);
    }

    #[test]
    fn short_text_is_kept_and_long_text_is_cut_at_a_character_boundary() {
        assert_eq!(excerpt("abc"), "abc");
        let long = "é".repeat(1000);
        let e = excerpt(&long);
        assert!(e.starts_with(&"é".repeat(MAX_EXCERPT)), "{e}");
        assert!(e.ends_with("… (1000 characters)"), "{e}");
    }
}
