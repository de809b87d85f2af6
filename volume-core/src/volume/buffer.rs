//! Voxel storage: owned, or borrowed zero-copy from a shared byte source.
//!
//! `formats` memory-maps a raw or NRRD file and hands the map over as a [`ByteSource`]; the
//! voxels are then viewed in place with `bytemuck` (alignment and size checked once, here),
//! so opening a 10 GB file reads nothing and copies nothing. Edits (thesis §7.6) copy on write.

use std::sync::Arc;

use crate::error::VolumeError;
use crate::voxel::{Voxel, VoxelType};

/// Bytes that outlive the volume viewing them (a memory map, a `Vec<u8>`, ...).
pub trait ByteSource: Send + Sync {
    fn bytes(&self) -> &[u8];
}

impl<T: AsRef<[u8]> + Send + Sync> ByteSource for T {
    fn bytes(&self) -> &[u8] {
        self.as_ref()
    }
}

#[derive(Clone)]
enum Storage<T> {
    Owned(Arc<Vec<T>>),
    Shared {
        source: Arc<dyn ByteSource>,
        byte_offset: usize,
        len: usize,
    },
}

/// A contiguous run of voxels of one native type.
#[derive(Clone)]
pub struct VoxelBuffer<T: Voxel> {
    storage: Storage<T>,
}

impl<T: Voxel> VoxelBuffer<T> {
    pub fn from_vec(voxels: Vec<T>) -> Self {
        Self {
            storage: Storage::Owned(Arc::new(voxels)),
        }
    }

    /// Views `len` native-endian voxels at `byte_offset` of `source` without copying.
    pub fn from_shared(
        source: Arc<dyn ByteSource>,
        byte_offset: usize,
        len: usize,
    ) -> Result<Self, VolumeError> {
        let size = size_of::<T>();
        let bytes = source.bytes();
        let needed = len.checked_mul(size).ok_or(VolumeError::SourceTooShort {
            offset: byte_offset,
            needed: usize::MAX,
            available: bytes.len(),
        })?;
        let end = byte_offset.checked_add(needed);
        if end.is_none_or(|e| e > bytes.len()) {
            return Err(VolumeError::SourceTooShort {
                offset: byte_offset,
                needed,
                available: bytes.len(),
            });
        }
        let ptr = bytes.as_ptr() as usize + byte_offset;
        if !ptr.is_multiple_of(align_of::<T>()) {
            return Err(VolumeError::Misaligned {
                offset: byte_offset,
                align: align_of::<T>(),
                voxel_type: T::TYPE.name(),
            });
        }
        Ok(Self {
            storage: Storage::Shared {
                source,
                byte_offset,
                len,
            },
        })
    }

    #[inline]
    pub fn as_slice(&self) -> &[T] {
        match &self.storage {
            Storage::Owned(v) => v.as_slice(),
            Storage::Shared {
                source,
                byte_offset,
                len,
            } => {
                let bytes = &source.bytes()[*byte_offset..*byte_offset + *len * size_of::<T>()];
                // Size and alignment were checked in `from_shared`.
                bytemuck::cast_slice(bytes)
            }
        }
    }

    /// Mutable access; a shared (mapped) buffer is first copied into owned memory.
    pub fn make_mut(&mut self) -> &mut Vec<T> {
        if let Storage::Shared { .. } = self.storage {
            self.storage = Storage::Owned(Arc::new(self.as_slice().to_vec()));
        }
        match &mut self.storage {
            Storage::Owned(v) => Arc::make_mut(v),
            Storage::Shared { .. } => unreachable!("converted to owned above"),
        }
    }

    pub fn len(&self) -> usize {
        match &self.storage {
            Storage::Owned(v) => v.len(),
            Storage::Shared { len, .. } => *len,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// True when the voxels are viewed in place in a shared source (e.g. a memory map).
    pub fn is_shared(&self) -> bool {
        matches!(self.storage, Storage::Shared { .. })
    }
}

crate::voxel_enum! {
    /// Voxels of any native type. Match once (with [`crate::dispatch_voxels!`]) and run
    /// generic code on the typed buffer; never match per voxel.
    #[derive(Clone)]
    pub enum VoxelData(VoxelBuffer)
}

/// Runs `$body` with `$buf` bound to the typed [`VoxelBuffer`] inside a [`VoxelData`]
/// ([`crate::match_voxel!`] for `VoxelData`).
#[macro_export]
macro_rules! dispatch_voxels {
    ($data:expr, $buf:ident => $body:expr) => {
        $crate::match_voxel!($crate::VoxelData, $data, $buf => $body)
    };
}

impl VoxelData {
    pub fn len(&self) -> usize {
        dispatch_voxels!(self, b => b.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn is_shared(&self) -> bool {
        dispatch_voxels!(self, b => b.is_shared())
    }

    /// Size of the voxels in bytes.
    pub fn size_bytes(&self) -> usize {
        self.len() * self.voxel_type().size_bytes()
    }

    /// Views `len` native-endian voxels of type `voxel_type` at `byte_offset` in `source`.
    pub fn from_shared(
        voxel_type: VoxelType,
        source: Arc<dyn ByteSource>,
        byte_offset: usize,
        len: usize,
    ) -> Result<Self, VolumeError> {
        Ok(crate::match_voxel_type!(voxel_type, V => {
            VoxelBuffer::<V>::from_shared(source, byte_offset, len)?.into()
        }))
    }
}

impl<T: Voxel> From<Vec<T>> for VoxelData
where
    VoxelData: From<VoxelBuffer<T>>,
{
    fn from(v: Vec<T>) -> Self {
        VoxelBuffer::from_vec(v).into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_view_reads_in_place_and_checks_bounds_and_alignment() {
        let bytes: Vec<u8> = [1u16, 2, 3, 4]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        let src: Arc<dyn ByteSource> = Arc::new(bytes);
        let buf = VoxelBuffer::<u16>::from_shared(src.clone(), 2, 3).unwrap();
        assert_eq!(buf.as_slice(), &[2, 3, 4]);
        assert!(buf.is_shared());
        assert!(matches!(
            VoxelBuffer::<u16>::from_shared(src.clone(), 2, 4),
            Err(VolumeError::SourceTooShort { .. })
        ));
        assert!(matches!(
            VoxelBuffer::<u16>::from_shared(src.clone(), 1, 1),
            Err(VolumeError::Misaligned { .. })
        ));
        assert!(matches!(
            VoxelBuffer::<u16>::from_shared(src, 0, usize::MAX),
            Err(VolumeError::SourceTooShort { .. })
        ));
    }

    #[test]
    fn make_mut_copies_shared_data_on_write() {
        let src: Arc<dyn ByteSource> = Arc::new(vec![5u8, 6, 7]);
        let mut buf = VoxelBuffer::<u8>::from_shared(src.clone(), 0, 3).unwrap();
        buf.make_mut()[0] = 9;
        assert_eq!(buf.as_slice(), &[9, 6, 7]);
        assert_eq!(src.bytes(), &[5, 6, 7]);
        assert!(!buf.is_shared());
    }
}
