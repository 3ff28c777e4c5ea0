//! Spec strings: `term ('+' suffix)*`, `term := name ('(' spec ')')?`, e.g.
//! `fa(eon)+retro`, `btdf(gtr)+scale+peraxis`. Parsing gives syntax only; the registry
//! builds a node tree from it.

use super::SpecError;

/// Parsed spec syntax.
#[derive(Clone, Debug, PartialEq)]
pub enum Ast {
    Term { name: String, arg: Option<Box<Ast>> },
    Suffix { inner: Box<Ast>, name: String },
}

impl Ast {
    pub fn parse(s: &str) -> Result<Ast, SpecError> {
        let err = |msg: String| SpecError::Parse {
            spec: s.to_string(),
            msg,
        };
        if s.is_empty() {
            return Err(err("empty spec".into()));
        }
        let (ast, rest) = parse_spec(s).map_err(err)?;
        if !rest.is_empty() {
            return Err(SpecError::Parse {
                spec: s.to_string(),
                msg: format!("unexpected '{rest}'"),
            });
        }
        Ok(ast)
    }
}

fn parse_ident(s: &str) -> Result<(String, &str), String> {
    let end = s
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    if end == 0 {
        return Err(format!("expected a model name at '{s}'"));
    }
    Ok((s[..end].to_ascii_lowercase(), &s[end..]))
}

fn parse_spec(s: &str) -> Result<(Ast, &str), String> {
    let (name, mut rest) = parse_ident(s)?;
    let mut ast = if let Some(r) = rest.strip_prefix('(') {
        let (inner, r) = parse_spec(r)?;
        let r = r
            .strip_prefix(')')
            .ok_or_else(|| format!("missing ')' after '{}'", &s[..s.len() - r.len()]))?;
        rest = r;
        Ast::Term {
            name,
            arg: Some(Box::new(inner)),
        }
    } else {
        Ast::Term { name, arg: None }
    };
    while let Some(r) = rest.strip_prefix('+') {
        let (suffix, r) = parse_ident(r)?;
        ast = Ast::Suffix {
            inner: Box::new(ast),
            name: suffix,
        };
        rest = r;
    }
    Ok((ast, rest))
}

/// Spec text of a syntax tree (the inverse of [`Ast::parse`]).
pub fn render_spec(ast: &Ast) -> String {
    match ast {
        Ast::Term { name, arg: None } => name.clone(),
        Ast::Term { name, arg: Some(a) } => format!("{name}({})", render_spec(a)),
        Ast::Suffix { inner, name } => format!("{}+{name}", render_spec(inner)),
    }
}
