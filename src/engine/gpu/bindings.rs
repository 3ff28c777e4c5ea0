//! The kernels' bindings and their uniform block, declared once: the bind group layout,
//! the bind groups and the WGSL declarations (`wgsl_declarations`, which every composed
//! module starts with) all follow these tables, so the Rust side and the WGSL side cannot
//! number or type a binding differently.

/// What a binding is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// The [`Dims`] block.
    Uniform,
    /// A storage buffer of `array<T>`.
    Storage { read_only: bool },
    /// A 2D texture read with `textureLoad` (never sampled), of f32 or u32 texels.
    Texture { uint: bool },
}

/// One binding of group 0.
#[derive(Clone, Copy, Debug)]
pub struct Binding {
    pub slot: u32,
    /// Its name in the WGSL modules.
    pub name: &'static str,
    pub kind: BindingKind,
    /// Its WGSL type.
    pub wgsl_type: &'static str,
    /// What it holds (emitted as a comment above its declaration).
    pub about: &'static str,
}

/// The bindings, in slot order (`Bind` names them on the Rust side).
pub const BINDINGS: [Binding; 8] = [
    Binding {
        slot: 0,
        name: "dims",
        kind: BindingKind::Uniform,
        wgsl_type: "Dims",
        about: "sizes of this pass (src/engine/gpu/bindings.rs, `Dim`)",
    },
    Binding {
        slot: 1,
        name: "records",
        kind: BindingKind::Texture { uint: false },
        wgsl_type: "texture_2d<f32>",
        about: "the sample records of the bound segment (kernel.wgsl, `record_texel`)",
    },
    Binding {
        slot: 2,
        name: "tables",
        kind: BindingKind::Storage { read_only: true },
        wgsl_type: "array<u32>",
        about: "per problem: its records and samples, then its μ table",
    },
    Binding {
        slot: 3,
        name: "params",
        kind: BindingKind::Storage { read_only: true },
        wgsl_type: "array<f32>",
        about: "the candidates' flat parameter vectors",
    },
    Binding {
        slot: 4,
        name: "out",
        kind: BindingKind::Storage { read_only: false },
        wgsl_type: "array<f32>",
        about: "partial costs per (candidate, tile), or model values per record slot",
    },
    Binding {
        slot: 5,
        name: "LUT",
        kind: BindingKind::Texture { uint: false },
        wgsl_type: "texture_2d<f32>",
        about: "the model's lookup table (GG's Smith Λ), LUT_WIDTH entries a row",
    },
    Binding {
        slot: 6,
        name: "owners",
        kind: BindingKind::Storage { read_only: true },
        wgsl_type: "array<u32>",
        about: "per candidate: its problem, and where its values start in `out`",
    },
    Binding {
        slot: 7,
        name: "normal_out",
        kind: BindingKind::Storage { read_only: false },
        wgsl_type: "array<f32>",
        about: "LM's normal-equation sums per (group, tile) (normal.wgsl)",
    },
];

/// Every binding, in slot order.
pub fn all() -> impl Iterator<Item = &'static Binding> {
    BINDINGS.iter()
}

/// The fields of the uniform block `Dims`, in order, one u32 each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum Dim {
    /// Candidates in this submission.
    NCandidates,
    /// Problems of the evaluator (the length of the first part of `tables`).
    NProblems,
    /// P, parameters per candidate.
    Dim,
    /// Workgroups along x of the evaluation grid (candidate blocks; y carries the rest).
    GroupsX,
    /// Groups of P + 1 candidates of the `normal` pass, and its workgroups along x.
    NGroups,
    NormalGroupsX,
    /// Always 2: the trip count of kernel.wgsl's `loops_completed` probe.
    ProbeTrips,
    /// The number of the bound records texture's first record.
    SegFirst,
    /// The pass's window of record numbers [WinFirst, WinEnd).
    WinFirst,
    WinEnd,
    /// Records per tile, and tiles per window (workgroups along z).
    Tile,
    NTiles,
    /// Always 0, but not a constant the shader compiler can see: kernel.wgsl's `opaque`
    /// ORs it into the intermediates of the compensated sums, so that no compiler can
    /// reassociate their rounding errors away (NVIDIA's driver did: tests/gpu_accuracy.rs).
    OpaqueZero,
}

/// The names of [`Dim`]'s fields in WGSL, in order, then the padding to 16 bytes.
pub const DIM_NAMES: [&str; 16] = [
    "n_candidates",
    "n_problems",
    "dim",
    "groups_x",
    "n_groups",
    "normal_groups_x",
    "probe_trips",
    "seg_first",
    "win_first",
    "win_end",
    "tile",
    "n_tiles",
    "opaque_zero",
    "pad_0",
    "pad_1",
    "pad_2",
];

/// The uniform block's contents ([`Dim`] indexes it), padded to 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Dims(pub [u32; 16]);

impl Dims {
    pub fn set(&mut self, d: Dim, v: u32) -> &mut Self {
        self.0[d as usize] = v;
        self
    }
    pub fn get(&self, d: Dim) -> u32 {
        self.0[d as usize]
    }
}

/// The WGSL of every binding and of the `Dims` block, which every kernel module starts
/// with.
pub fn wgsl_declarations() -> String {
    let mut src = String::from(
        "// ---- generated: bindings and uniform block (src/engine/gpu/bindings.rs)\nstruct Dims {\n",
    );
    for name in DIM_NAMES {
        src += &format!("    {name}: u32,\n");
    }
    src += "}\n";
    for b in all() {
        let var = match b.kind {
            BindingKind::Uniform => "var<uniform>".to_string(),
            BindingKind::Storage { read_only: true } => "var<storage, read>".to_string(),
            BindingKind::Storage { read_only: false } => "var<storage, read_write>".to_string(),
            BindingKind::Texture { .. } => "var".to_string(),
        };
        src += &format!(
            "// {}\n@group(0) @binding({}) {var} {}: {};\n",
            b.about, b.slot, b.name, b.wgsl_type
        );
    }
    src + "\n"
}

/// The bind group layout's entries.
pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    all()
        .map(|b| wgpu::BindGroupLayoutEntry {
            binding: b.slot,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: match b.kind {
                BindingKind::Uniform => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                BindingKind::Storage { read_only } => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                BindingKind::Texture { uint } => wgpu::BindingType::Texture {
                    sample_type: if uint {
                        wgpu::TextureSampleType::Uint
                    } else {
                        wgpu::TextureSampleType::Float { filterable: false }
                    },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
            },
            count: None,
        })
        .collect()
}

/// One resource per binding, by name.
pub enum Resource<'a> {
    Buffer(&'a wgpu::Buffer),
    Texture(&'a wgpu::TextureView),
}

/// A bind group from `(name, resource)` pairs: every binding given exactly once, a
/// buffer where the table declares one and a texture where it declares a texture.
pub fn bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    resources: &[(&str, Resource)],
) -> anyhow::Result<wgpu::BindGroup> {
    let mut entries = Vec::with_capacity(resources.len());
    for b in all() {
        let found: Vec<&Resource> = resources
            .iter()
            .filter(|(n, _)| *n == b.name)
            .map(|(_, r)| r)
            .collect();
        let [r] = found[..] else {
            anyhow::bail!("binding `{}` given {} times", b.name, found.len());
        };
        let resource = match (r, b.kind) {
            (Resource::Buffer(buf), BindingKind::Uniform | BindingKind::Storage { .. }) => {
                buf.as_entire_binding()
            }
            (Resource::Texture(view), BindingKind::Texture { .. }) => {
                wgpu::BindingResource::TextureView(view)
            }
            _ => anyhow::bail!("binding `{}` given the wrong kind of resource", b.name),
        };
        entries.push(wgpu::BindGroupEntry {
            binding: b.slot,
            resource,
        });
    }
    anyhow::ensure!(
        resources.len() == entries.len(),
        "a resource names no binding"
    );
    Ok(device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("bsdfit kernel"),
        layout,
        entries: &entries,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tables_agree_with_each_other() {
        assert_eq!(DIM_NAMES.len(), std::mem::size_of::<Dims>() / 4);
        assert_eq!(
            std::mem::size_of::<Dims>() % 16,
            0,
            "a uniform block is 16-byte sized"
        );
        const DIM_COUNT: usize = Dim::OpaqueZero as usize + 1;
        assert_eq!(DIM_NAMES[DIM_COUNT - 1], "opaque_zero");
        assert!(DIM_NAMES[DIM_COUNT..].iter().all(|n| n.starts_with("pad_")));
        for (i, b) in all().enumerate() {
            assert_eq!(b.slot as usize, i, "slots are dense and in order");
        }
        let src = wgsl_declarations();
        assert!(
            src.contains("@group(0) @binding(7) var<storage, read_write> normal_out: array<f32>;")
        );
        assert!(src.contains("    win_end: u32,"));
    }
}
