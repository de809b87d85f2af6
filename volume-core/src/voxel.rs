//! Native voxel types.
//!
//! Voxels keep the type they were stored in: a `u8` CT volume is traversed and bounded in
//! `u8` (its min/max kd-tree too), which is what keeps memory small. Generic code is written
//! against [`Voxel`]; code that holds a volume of unknown type matches on
//! [`crate::VoxelData`] once, outside any hot loop, with [`crate::dispatch_voxels!`].
//!
//! The eight types are listed once, in [`crate::for_each_voxel_type!`]: the per-type
//! enums ([`crate::voxel_enum!`]) and the matches over them ([`crate::match_voxel!`],
//! [`crate::match_voxel_type!`]) are generated from that list.

use std::fmt::Debug;

/// The voxel types a volume can hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VoxelType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl VoxelType {
    pub const ALL: [VoxelType; 8] = [
        VoxelType::U8,
        VoxelType::I8,
        VoxelType::U16,
        VoxelType::I16,
        VoxelType::U32,
        VoxelType::I32,
        VoxelType::F32,
        VoxelType::F64,
    ];

    /// Size of one voxel in bytes.
    pub const fn size_bytes(self) -> usize {
        match self {
            VoxelType::U8 | VoxelType::I8 => 1,
            VoxelType::U16 | VoxelType::I16 => 2,
            VoxelType::U32 | VoxelType::I32 | VoxelType::F32 => 4,
            VoxelType::F64 => 8,
        }
    }

    /// The short name used on the command line and in `info --json` ("u8", "i16", "f32", ...).
    pub const fn name(self) -> &'static str {
        match self {
            VoxelType::U8 => "u8",
            VoxelType::I8 => "i8",
            VoxelType::U16 => "u16",
            VoxelType::I16 => "i16",
            VoxelType::U32 => "u32",
            VoxelType::I32 => "i32",
            VoxelType::F32 => "f32",
            VoxelType::F64 => "f64",
        }
    }

    /// Parses the short name (see [`VoxelType::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    pub const fn is_float(self) -> bool {
        matches!(self, VoxelType::F32 | VoxelType::F64)
    }
}

impl std::fmt::Display for VoxelType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A voxel scalar in its native type.
///
/// `is_void` is true for NaN: NaN voxels are "no data" and never bound an isosurface.
pub trait Voxel: bytemuck::Pod + PartialOrd + Default + Send + Sync + Debug + 'static {
    const TYPE: VoxelType;
    /// The smallest and largest representable values (finite for floats).
    const LOWEST: Self;
    const HIGHEST: Self;

    fn to_f32(self) -> f32;
    fn to_f64(self) -> f64;
    /// Rounds and saturates `v` to this type (NaN becomes 0 for integers).
    fn from_f64(v: f64) -> Self;
    /// True for NaN: a void sample.
    fn is_void(self) -> bool;
    /// Byte-swaps in place (for reading data of the other endianness).
    fn swap_bytes(self) -> Self;
}

macro_rules! impl_int_voxel {
    ($t:ty, $tag:ident) => {
        impl Voxel for $t {
            const TYPE: VoxelType = VoxelType::$tag;
            const LOWEST: Self = <$t>::MIN;
            const HIGHEST: Self = <$t>::MAX;
            #[inline(always)]
            fn to_f32(self) -> f32 {
                self as f32
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn from_f64(v: f64) -> Self {
                // `as` saturates and maps NaN to 0.
                v.round() as $t
            }
            #[inline(always)]
            fn is_void(self) -> bool {
                false
            }
            #[inline]
            fn swap_bytes(self) -> Self {
                <$t>::swap_bytes(self)
            }
        }
    };
}

impl_int_voxel!(u8, U8);
impl_int_voxel!(i8, I8);
impl_int_voxel!(u16, U16);
impl_int_voxel!(i16, I16);
impl_int_voxel!(u32, U32);
impl_int_voxel!(i32, I32);

impl Voxel for f32 {
    const TYPE: VoxelType = VoxelType::F32;
    const LOWEST: Self = f32::MIN;
    const HIGHEST: Self = f32::MAX;
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn is_void(self) -> bool {
        self.is_nan()
    }
    #[inline]
    fn swap_bytes(self) -> Self {
        f32::from_bits(self.to_bits().swap_bytes())
    }
}

impl Voxel for f64 {
    const TYPE: VoxelType = VoxelType::F64;
    const LOWEST: Self = f64::MIN;
    const HIGHEST: Self = f64::MAX;
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn is_void(self) -> bool {
        self.is_nan()
    }
    #[inline]
    fn swap_bytes(self) -> Self {
        f64::from_bits(self.to_bits().swap_bytes())
    }
}

/// The one list of voxel types: calls `$callback! { $args ; U8 u8, I8 i8, ... }` with each
/// [`VoxelType`] variant next to its Rust type. Every per-type enum ([`crate::VoxelData`],
/// [`crate::grid::AnyGridScene`], [`crate::ooc::AnyOocVolume`]) and every match over voxel
/// types is generated from it, through [`crate::voxel_enum!`], [`crate::match_voxel!`] and
/// [`crate::match_voxel_type!`].
#[macro_export]
macro_rules! for_each_voxel_type {
    ($($callback:ident)::+, $($args:tt)*) => {
        $($callback)::+! {
            $($args)* ;
            U8 u8, I8 i8, U16 u16, I16 i16, U32 u32, I32 i32, F32 f32, F64 f64
        }
    };
}

/// Declares an enum with one variant per voxel type, each holding `$inner<T>` (variants
/// named as in [`VoxelType`]), with `voxel_type()` and `From<$inner<T>>` for every type.
/// Match it with [`crate::match_voxel!`].
#[macro_export]
macro_rules! voxel_enum {
    ($(#[$meta:meta])* $vis:vis enum $name:ident($inner:ident)) => {
        $crate::for_each_voxel_type!($crate::voxel_enum, @declare $(#[$meta])* $vis enum $name($inner));
    };
    (@declare $(#[$meta:meta])* $vis:vis enum $name:ident($inner:ident); $($tag:ident $t:ty),*) => {
        $(#[$meta])*
        $vis enum $name {
            $($tag($inner<$t>),)*
        }

        impl $name {
            /// The voxel type of the variant.
            pub fn voxel_type(&self) -> $crate::VoxelType {
                match self {
                    $(Self::$tag(_) => $crate::VoxelType::$tag,)*
                }
            }
        }

        $(
            impl From<$inner<$t>> for $name {
                fn from(x: $inner<$t>) -> Self {
                    Self::$tag(x)
                }
            }
        )*
    };
}

/// Runs `$body` with `$x` bound to the typed value inside `$value`, an enum made by
/// [`crate::voxel_enum!`] (`$enum` is its type). Match once, outside any hot loop, and
/// run generic code on the typed value. The second form matches two such enums together
/// (`match_voxel!(A, a, x; B, b, y => same_type(x, y); else different())`).
#[macro_export]
macro_rules! match_voxel {
    (@arms ($enum:ty) ($value:expr) $x:ident ($body:expr); $($tag:ident $t:ty),*) => {{
        type VoxelEnumOfMatch = $enum;
        match $value {
            $(VoxelEnumOfMatch::$tag($x) => $body,)*
        }
    }};
    (@pairs ($e1:ty) ($v1:expr) $x1:ident ($e2:ty) ($v2:expr) $x2:ident ($body:expr) ($other:expr);
        $($tag:ident $t:ty),*) => {{
        type FirstVoxelEnum = $e1;
        type SecondVoxelEnum = $e2;
        match ($v1, $v2) {
            $((FirstVoxelEnum::$tag($x1), SecondVoxelEnum::$tag($x2)) => $body,)*
            _ => $other,
        }
    }};
    ($enum:ty, $value:expr, $x:ident => $body:expr) => {
        $crate::for_each_voxel_type!($crate::match_voxel, @arms ($enum) ($value) $x ($body))
    };
    // Two enums at once: `$body` where both hold the same voxel type, else `$other`.
    ($e1:ty, $v1:expr, $x1:ident; $e2:ty, $v2:expr, $x2:ident => $body:expr; else $other:expr) => {
        $crate::for_each_voxel_type!(
            $crate::match_voxel, @pairs ($e1) ($v1) $x1 ($e2) ($v2) $x2 ($body) ($other)
        )
    };
}

/// Runs `$body` with the type name `$t` bound to the Rust type of the [`VoxelType`]
/// `$voxel_type` (`match_voxel_type!(ty, T => VoxelBuffer::<T>::from_vec(..).into())`).
#[macro_export]
macro_rules! match_voxel_type {
    ($voxel_type:expr, $t:ident => $body:expr) => {
        $crate::for_each_voxel_type!($crate::match_voxel_type, @arms ($voxel_type) $t ($body))
    };
    (@arms ($voxel_type:expr) $t:ident ($body:expr); $($tag:ident $ty:ty),*) => {
        match $voxel_type {
            $($crate::VoxelType::$tag => {
                type $t = $ty;
                $body
            })*
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_sizes_match_rust_types() {
        for t in VoxelType::ALL {
            assert_eq!(VoxelType::from_name(t.name()), Some(t));
        }
        assert_eq!(VoxelType::I16.size_bytes(), size_of::<i16>());
        assert_eq!(VoxelType::F64.size_bytes(), size_of::<f64>());
        assert_eq!(VoxelType::from_name("float"), None);
    }

    #[test]
    fn from_f64_saturates_and_rounds() {
        assert_eq!(u8::from_f64(300.0), 255);
        assert_eq!(u8::from_f64(-4.0), 0);
        assert_eq!(i16::from_f64(2.6), 3);
        assert_eq!(u16::from_f64(f64::NAN), 0);
        assert!(f32::NAN.is_void());
        assert!(!0u8.is_void());
    }

    #[test]
    fn swap_bytes_is_an_involution() {
        assert_eq!(0x1234u16.swap_bytes(), 0x3412);
        let x = 1.5f32;
        assert_eq!(Voxel::swap_bytes(Voxel::swap_bytes(x)), x);
        assert_eq!(
            Voxel::swap_bytes(1.0f64).to_bits(),
            1.0f64.to_bits().swap_bytes()
        );
    }
}
