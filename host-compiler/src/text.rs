//! Quoting user text in messages: an excerpt of bounded length, so that a huge line, field or header
//! (a row of a million columns) is never echoed whole into an error.

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_text_is_kept_and_long_text_is_cut_at_a_character_boundary() {
        assert_eq!(excerpt("abc"), "abc");
        let long = "é".repeat(1000);
        let e = excerpt(&long);
        assert!(e.starts_with(&"é".repeat(MAX_EXCERPT)), "{e}");
        assert!(e.ends_with("… (1000 characters)"), "{e}");
    }
}
