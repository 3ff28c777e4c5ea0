//! Placeholder: being implemented.
use super::{Ast, Node};
pub fn build(_arg: Option<&Ast>) -> Result<Node, String> {
    Err("'btdf' is not implemented yet".into())
}
pub fn build_scale(_n: Node) -> Result<Node, String> {
    Err("'+scale' is not implemented yet".into())
}
pub fn build_absorb(_n: Node) -> Result<Node, String> {
    Err("'+absorb' is not implemented yet".into())
}
pub fn build_diffuse(_n: Node) -> Result<Node, String> {
    Err("'+diffuse' is not implemented yet".into())
}
