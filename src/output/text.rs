//! Words of messages shared by the command line and the workflows.

/// "1 fit", "2 fits": `n` and the noun, plural when n ≠ 1 (nouns ending in s get "es"
/// only if given; pass the plural form for irregular ones via [`plural_with`]).
pub fn plural(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// `n` with the singular or the given plural noun.
pub fn plural_with(n: usize, one: &str, many: &str) -> String {
    if n == 1 {
        format!("1 {one}")
    } else {
        format!("{n} {many}")
    }
}
