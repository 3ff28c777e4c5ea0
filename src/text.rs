//! Words of messages shared by every layer: counts with their nouns, and the text of a
//! caught panic.

/// "1 fit", "2 fits": `n` and the noun, plural when n ≠ 1 (nouns ending in s get "es"
/// only if given; pass the plural form for irregular ones via [`plural_with`]).
pub fn plural(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// `n` with the singular or the given plural noun ("1 sample", "2 samples"); an empty
/// noun gives the bare number.
pub fn plural_with(n: usize, one: &str, many: &str) -> String {
    let noun = if n == 1 { one } else { many };
    if noun.is_empty() {
        n.to_string()
    } else {
        format!("{n} {noun}")
    }
}

/// The message a caught panic carries (`panic!` with a literal or a formatted text), if
/// it carries one.
pub fn panic_text(payload: &(dyn std::any::Any + Send)) -> Option<&str> {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
}

#[cfg(test)]
mod tests {
    use super::panic_text;

    #[test]
    fn a_panic_says_its_message_or_nothing() {
        let caught = |f: fn()| std::panic::catch_unwind(f).unwrap_err();
        assert_eq!(
            panic_text(caught(|| panic!("a literal")).as_ref()),
            Some("a literal")
        );
        assert_eq!(
            panic_text(caught(|| panic!("row {}", 7)).as_ref()),
            Some("row 7")
        );
        assert_eq!(
            panic_text(caught(|| std::panic::panic_any(3u8)).as_ref()),
            None
        );
    }
}
