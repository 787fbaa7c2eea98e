//! The line of a dotted key path (`test.settle.window_s`,
//! `test.levels_V[1]`) in a TOML text, so that a validation error names
//! the line as well as the key. A key the text leaves out (a default)
//! gets the line of the deepest part of its path the text has.

use toml::de::{DeTable, DeValue};

/// The 1-based line of `key` (dotted, with `[n]` for array elements) in
/// `text`; `None` when the text does not parse or has no part of the path.
pub fn key_line(text: &str, key: &str) -> Option<usize> {
    let doc = DeTable::parse(text).ok()?;
    let mut value: Option<&DeValue> = None;
    let mut table = doc.get_ref();
    let mut at = None;
    'path: for part in key.split('.') {
        let (name, indices) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if let Some(v) = value {
            match v {
                DeValue::Table(t) => table = t,
                _ => break,
            }
        }
        let Some((k, v)) = table.iter().find(|(k, _)| k.get_ref().as_ref() == name) else {
            break;
        };
        at = Some(k.span().start);
        let mut v = v;
        for index in indices
            .split(['[', ']'])
            .filter(|s| !s.is_empty())
            .map(str::parse::<usize>)
        {
            let element = match (v.get_ref(), index) {
                (DeValue::Array(a), Ok(n)) => a.get(n),
                _ => None,
            };
            let Some(e) = element else { break 'path };
            at = Some(e.span().start);
            v = e;
        }
        value = Some(v.get_ref());
    }
    let start = at?.min(text.len());
    Some(text[..start].matches('\n').count() + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "[rig]\nsample_rate_Hz = 2000\n\n[test]\nlevels_V = [\n  60,\n  248,\n]\n\
        [test.settle]\nwindow_s = 0.1\n";

    #[test]
    fn keys_array_elements_and_defaults_find_their_line() {
        assert_eq!(key_line(TEXT, "rig.sample_rate_Hz"), Some(2));
        assert_eq!(key_line(TEXT, "test.settle.window_s"), Some(10));
        assert_eq!(key_line(TEXT, "test.levels_V"), Some(5));
        assert_eq!(key_line(TEXT, "test.levels_V[1]"), Some(7));
        // Left out: the deepest part the text has.
        assert_eq!(key_line(TEXT, "test.levels_V[9]"), Some(5));
        assert_eq!(key_line(TEXT, "test.settle.hold_s"), Some(9));
        assert_eq!(key_line(TEXT, "supervisor.stale_timeout_s"), None);
        assert_eq!(key_line("not = [toml", "not"), None);
    }
}
