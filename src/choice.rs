//! Options in words both front ends share. A named choice is an option whose value is one
//! of a few words (`--backend auto`, `optimizer="lm"`): each such enum lists its values
//! once, with the word that names each and what it means, and both front ends read that
//! table (the command line builds its value parser and help from it, Python parses keyword
//! arguments with it). A [`FieldError`] is an option's value that fails a check, written
//! so that each front end names the options its own way (`--mc-scale`, `mc_scale`).

/// An enum whose values are named by words.
pub trait Choice: Copy + PartialEq + Sized + 'static {
    /// What the value is, in words, for messages (`backend`, `optimizer`).
    const WHAT: &'static str;
    /// Every value: itself, the word that names it, and what it means (one line).
    const TABLE: &'static [(Self, &'static str, &'static str)];

    /// The word that names this value.
    fn name(self) -> &'static str {
        Self::TABLE
            .iter()
            .find(|(v, _, _)| *v == self)
            .map_or("", |(_, name, _)| name)
    }

    /// The value a word names (ASCII case ignored), or an error listing the words.
    fn parse_choice(word: &str) -> Result<Self, ChoiceError> {
        Self::TABLE
            .iter()
            .find(|(_, name, _)| name.eq_ignore_ascii_case(word.trim()))
            .map(|(v, _, _)| *v)
            .ok_or_else(|| ChoiceError {
                what: Self::WHAT,
                word: word.to_string(),
                names: Self::TABLE.iter().map(|(_, name, _)| *name).collect(),
            })
    }
}

/// A word that names no value of a [`Choice`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChoiceError {
    pub what: &'static str,
    pub word: String,
    pub names: Vec<&'static str>,
}

impl std::fmt::Display for ChoiceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<String> = self.names.iter().map(|n| format!("'{n}'")).collect();
        write!(
            f,
            "{}: '{}' is not one of {}",
            self.what,
            self.word,
            names.join(", ")
        )
    }
}

impl std::error::Error for ChoiceError {}

/// `Display` and `FromStr` for a [`Choice`], from its table.
macro_rules! named_choice {
    ($ty:ty) => {
        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str($crate::choice::Choice::name(*self))
            }
        }
        impl std::str::FromStr for $ty {
            type Err = $crate::choice::ChoiceError;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                <$ty as $crate::choice::Choice>::parse_choice(s)
            }
        }
    };
}
pub(crate) use named_choice;

/// An option's value that fails a check. The message is a template that names options as
/// `{name}` or `{name=value}`, `name` in snake_case (the Python keyword): `Display` writes
/// them as Python spells them (`mc_scale`, `loss='chi2'`), and the command line renders
/// them as its flags (`--mc-scale`, `--loss chi2`) with [`FieldError::render`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldError {
    template: String,
}

impl FieldError {
    /// An error from its template (see the type's documentation).
    pub fn new(template: impl Into<String>) -> FieldError {
        FieldError {
            template: template.into(),
        }
    }

    /// The message with every `{name}` or `{name=value}` written by `option(name, value)`.
    pub fn render(&self, option: &dyn Fn(&str, Option<&str>) -> String) -> String {
        let mut out = String::new();
        let mut rest = self.template.as_str();
        while let Some(open) = rest.find('{') {
            out.push_str(&rest[..open]);
            let Some(close) = rest[open..].find('}') else {
                break;
            };
            let inner = &rest[open + 1..open + close];
            let (name, value) = match inner.split_once('=') {
                Some((name, value)) => (name, Some(value)),
                None => (inner, None),
            };
            // Only `{name}` and `{name=value}` name options; other braces are text.
            if !name.is_empty() && name.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                out.push_str(&option(name, value));
            } else {
                out.push_str(&rest[open..=open + close]);
            }
            rest = &rest[open + close + 1..];
        }
        out.push_str(rest);
        out
    }

    /// How Python names an option and its value: `name`, `name=1.5`, `name='chi2'`.
    pub fn python_style(name: &str, value: Option<&str>) -> String {
        match value {
            None => name.to_string(),
            Some(v) if v.parse::<f64>().is_ok() => format!("{name}={v}"),
            Some(v) => format!("{name}='{v}'"),
        }
    }
}

impl std::fmt::Display for FieldError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(&FieldError::python_style))
    }
}

impl std::error::Error for FieldError {}

/// An `anyhow` error carrying a [`FieldError`] made from `template`.
pub fn field_error(template: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(FieldError::new(template))
}

#[cfg(test)]
mod tests {
    use super::Choice;

    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Colour {
        Red,
        DarkBlue,
    }
    impl Choice for Colour {
        const WHAT: &'static str = "colour";
        const TABLE: &'static [(Self, &'static str, &'static str)] = &[
            (Colour::Red, "red", "the red one"),
            (Colour::DarkBlue, "dark-blue", "the blue one"),
        ];
    }
    crate::choice::named_choice!(Colour);

    #[test]
    fn field_errors_name_options_per_front_end() {
        let e =
            super::FieldError::new("{mc_scale} needs {mc} above 0, and {loss=chi2} or {n=2} {a b}");
        assert_eq!(
            e.to_string(),
            "mc_scale needs mc above 0, and loss='chi2' or n=2 {a b}"
        );
        let flag = |name: &str, value: Option<&str>| {
            let flag = format!("--{}", name.replace('_', "-"));
            value.map_or(flag.clone(), |v| format!("{flag} {v}"))
        };
        assert_eq!(
            e.render(&flag),
            "--mc-scale needs --mc above 0, and --loss chi2 or --n 2 {a b}"
        );
    }

    #[test]
    fn words_name_values_both_ways() {
        assert_eq!(Colour::DarkBlue.name(), "dark-blue");
        assert_eq!(Colour::DarkBlue.to_string(), "dark-blue");
        assert_eq!("Dark-Blue".parse::<Colour>(), Ok(Colour::DarkBlue));
        assert_eq!("red".parse::<Colour>(), Ok(Colour::Red));
        let e = "blue".parse::<Colour>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "colour: 'blue' is not one of 'red', 'dark-blue'"
        );
    }
}
