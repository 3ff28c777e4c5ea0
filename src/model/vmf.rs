//! Placeholder: being implemented.
use super::{Ast, Node};
pub fn build(_arg: Option<&Ast>) -> Result<Node, String> {
    Err("'vmf' is not implemented yet".into())
}
