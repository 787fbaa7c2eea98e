//! Excerpts of user input for error messages: an offending value is
//! quoted whole when short, and cut to its first characters and its size
//! when long, so that a 10 MB field of a CSV file or a long line of a
//! configuration does not flood the terminal or the log; a long list in
//! a message (the 36 parts a record was cut into) is shortened the same
//! way.

/// Characters of a long value shown before it is cut.
pub const EXCERPT_CHARS: usize = 40;

/// `s` quoted (Rust debug quoting) when it has at most [`EXCERPT_CHARS`]
/// characters; else its first ones quoted, then `…(N bytes)`.
pub fn quoted(s: &str) -> String {
    match s.char_indices().nth(EXCERPT_CHARS) {
        None => format!("{s:?}"),
        Some((cut, _)) => format!("{:?}…({} bytes)", &s[..cut], s.len()),
    }
}

/// `s` as it is when it has at most [`EXCERPT_CHARS`] characters; else
/// its first ones, then `…(N bytes)` (for text shown unquoted).
pub fn cut(s: &str) -> String {
    match s.char_indices().nth(EXCERPT_CHARS) {
        None => s.to_string(),
        Some((cut, _)) => format!("{}…({} bytes)", &s[..cut], s.len()),
    }
}

/// Items a list shows whole; a longer one shows its first
/// [`LIST_HEAD`] and last [`LIST_TAIL`].
pub const LIST_ITEMS: usize = 8;
/// Items shown before the cut of a long list.
pub const LIST_HEAD: usize = 3;
/// Items shown after the cut of a long list.
pub const LIST_TAIL: usize = 2;

/// `items` joined by commas when there are at most [`LIST_ITEMS`]; else
/// the first and last few around `…`, and how many there are in all.
pub fn listed(items: &[String]) -> String {
    if items.len() <= LIST_ITEMS {
        return items.join(", ");
    }
    format!(
        "{}, …, {} ({} in all)",
        items[..LIST_HEAD].join(", "),
        items[items.len() - LIST_TAIL..].join(", "),
        items.len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_list_shows_its_ends_and_its_count() {
        let items: Vec<String> = (0..36).map(|n| n.to_string()).collect();
        assert_eq!(listed(&items), "0, 1, 2, …, 34, 35 (36 in all)");
        assert_eq!(listed(&items[..8]), "0, 1, 2, 3, 4, 5, 6, 7");
        assert_eq!(listed(&[]), "");
    }

    #[test]
    fn short_values_are_whole_and_long_ones_cut_with_their_size() {
        assert_eq!(quoted("abc"), "\"abc\"");
        assert_eq!(cut("abc"), "abc");
        let long = "x".repeat(10_000_000);
        let q = quoted(&long);
        assert_eq!(q, format!("\"{}\"…(10000000 bytes)", "x".repeat(40)));
        assert_eq!(cut(&long), format!("{}…(10000000 bytes)", "x".repeat(40)));
        // Cut on a character boundary.
        let wide = "é".repeat(50);
        assert_eq!(cut(&wide), format!("{}…(100 bytes)", "é".repeat(40)));
    }
}
