//! What node functions are handed: the parameters of the channels evaluated together
//! ([`Channels`]), the children's values ([`Children`]), direction pairs ([`Dir`]), and
//! the helper of their loops ([`each_direction`]).

use glam::DVec3;

/// Most children a node may have ([`Node::eval`] and the default
/// [`Bsdf::eval_channels`] gather them on the stack).
pub const MAX_CHILDREN: usize = 4;

/// The parameters of the channels evaluated together ([`Bsdf::eval_channels`]): channel
/// i reads the scalar view of its group (its channel, and its plane under `+peraxis`),
/// restricted to one node's parameters. Every direction of one call has the same
/// channels.
///
/// The views of one call differ only in their rgb parameters: the channels of one call
/// lie on one plane, so every shared (and per-plane) parameter has one value for all of
/// them, and a node may read those from channel 0.
#[derive(Clone, Copy, Debug)]
pub struct Channels<'a> {
    /// Every group's scalar view, one after the other, `stride` values each.
    scalars: &'a [f64],
    stride: usize,
    /// The group of each channel evaluated (several channels may name the same group:
    /// repeated measurements).
    groups: &'a [u32],
    /// This node's first parameter in a view, and its parameter count.
    offset: usize,
    nparams: usize,
}

impl<'a> Channels<'a> {
    /// The channels `groups` of the views `scalars` (`stride` = [`Model::scalar_count`]
    /// values per group, [`Model::views_into`]), at the root of the tree.
    pub fn new(scalars: &'a [f64], stride: usize, groups: &'a [u32]) -> Channels<'a> {
        Channels {
            scalars,
            stride,
            groups,
            offset: 0,
            nparams: stride,
        }
    }
    /// One channel whose view is `p` (what [`Bsdf::eval`] takes).
    pub fn one(p: &'a [f64]) -> Channels<'a> {
        Channels {
            scalars: p,
            stride: p.len(),
            groups: &[0],
            offset: 0,
            nparams: p.len(),
        }
    }
    /// Channel 0 alone (a subtree with no rgb parameter has one value for all).
    pub(super) fn first(&self) -> Channels<'a> {
        Channels {
            groups: &self.groups[..1],
            ..*self
        }
    }
    /// Number of channels evaluated.
    pub fn len(&self) -> usize {
        self.groups.len()
    }
    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }
    /// The node's parameters for channel i (what [`Bsdf::eval`] takes as `p`).
    #[inline]
    pub fn view(&self, i: usize) -> &'a [f64] {
        let at = self.groups[i] as usize * self.stride + self.offset;
        &self.scalars[at..at + self.nparams]
    }
    /// The node's parameter count.
    pub fn count(&self) -> usize {
        self.nparams
    }
    /// Parameter j of the node for channel i.
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        debug_assert!(j < self.nparams);
        self.scalars[self.groups[i] as usize * self.stride + self.offset + j]
    }
    /// The whole scalar view of channel i (what [`Node::eval`] takes).
    #[inline]
    pub(super) fn full_view(&self, i: usize) -> &'a [f64] {
        let at = self.groups[i] as usize * self.stride;
        &self.scalars[at..at + self.stride]
    }
    /// The same channels, restricted to a node's parameters.
    #[inline]
    pub(super) fn node(&self, offset: usize, nparams: usize) -> Channels<'a> {
        Channels {
            offset,
            nparams,
            ..*self
        }
    }
}

/// A direction pair (ωi, ωo).
pub type Dir = (DVec3, DVec3);

/// The children's values for a block of m directions × n channels
/// ([`Bsdf::eval_channels`]): child k at direction d, channel i is
/// `values[(k · m + d) · n + i]`.
#[derive(Clone, Copy, Debug)]
pub struct Children<'a> {
    pub(super) values: &'a [f64],
    m: usize,
    n: usize,
}

impl<'a> Children<'a> {
    pub fn new(values: &'a [f64], m: usize, n: usize) -> Children<'a> {
        Children { values, m, n }
    }
    /// Child k's values at direction d, one per channel.
    #[inline]
    pub fn at(&self, k: usize, d: usize) -> &'a [f64] {
        let at = (k * self.m + d) * self.n;
        &self.values[at..at + self.n]
    }
}

/// Calls `f(d, ωi, ωo, out_d)` for every direction d of a block, `out_d` its n values
/// in `out` (direction-major): the loop of an [`Bsdf::eval_channels`] override, inlined
/// into it so that the per-direction body is not a call.
#[inline]
pub fn each_direction(
    dirs: &[Dir],
    n: usize,
    out: &mut [f64],
    mut f: impl FnMut(usize, DVec3, DVec3, &mut [f64]),
) {
    if n == 0 {
        return;
    }
    for (d, (&(wi, wo), o)) in dirs.iter().zip(out.chunks_exact_mut(n)).enumerate() {
        f(d, wi, wo, o);
    }
}
