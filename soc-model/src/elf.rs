//! Loading an RV32 ELF image: the file bytes of its PT_LOAD segments.

use crate::{RAM_BASE, RAM_SIZE};

/// Why an ELF image cannot be loaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LoadError {
    /// Not a readable ELF file (truncated, bad headers, segment data outside the file).
    Parse(String),
    /// Not a 32-bit little-endian RISC-V image.
    WrongMachine {
        /// The architecture the file names.
        architecture: String,
    },
    /// The entry point is not the reset address (`RAM_BASE`).
    Entry {
        /// The file's entry point.
        entry: u64,
    },
    /// A loadable segment's file bytes do not lie inside RAM.
    OutsideRam {
        /// Load address of the segment.
        addr: u64,
        /// Its length in bytes.
        len: u64,
    },
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Parse(why) => write!(f, "not a readable ELF file: {why}"),
            Self::WrongMachine { architecture } => {
                write!(f, "not an RV32 image (architecture {architecture})")
            }
            Self::Entry { entry } => write!(
                f,
                "entry point {entry:#x} is not the reset address {RAM_BASE:#x}"
            ),
            Self::OutsideRam { addr, len } => {
                write!(f, "segment of {len} bytes at {addr:#x} does not fit in RAM")
            }
        }
    }
}

impl std::error::Error for LoadError {}

/// A PT_LOAD segment of an image: where its file bytes go in RAM.
pub(crate) struct Segment<'a> {
    /// RAM byte offset.
    pub off: usize,
    /// The file bytes.
    pub data: &'a [u8],
    /// Whether the segment is executable (`PF_X`).
    pub exec: bool,
}

/// The PT_LOAD segments of an RV32 ELF image; the zero-filled tails are left to zeroed RAM.
/// The entry point must be [`RAM_BASE`].
pub(crate) fn segments(elf: &[u8]) -> Result<Vec<Segment<'_>>, LoadError> {
    use object::read::elf::{ElfFile32, FileHeader, ProgramHeader};
    use object::{Architecture, Object};
    let file = ElfFile32::<object::LittleEndian>::parse(elf)
        .map_err(|e| LoadError::Parse(e.to_string()))?;
    if file.architecture() != Architecture::Riscv32 {
        return Err(LoadError::WrongMachine {
            architecture: format!("{:?}", file.architecture()),
        });
    }
    if file.entry() != u64::from(RAM_BASE) {
        return Err(LoadError::Entry {
            entry: file.entry(),
        });
    }
    let endian = file.endian();
    let headers = file
        .elf_header()
        .program_headers(endian, elf)
        .map_err(|e| LoadError::Parse(e.to_string()))?;
    let mut out = Vec::new();
    for ph in headers {
        if ph.p_type(endian) != object::elf::PT_LOAD || ph.p_filesz(endian) == 0 {
            continue;
        }
        let addr = u64::from(ph.p_paddr(endian));
        let data = ph
            .data(endian, elf)
            .map_err(|()| LoadError::Parse("segment data outside the file".into()))?;
        let len = data.len() as u64;
        let off = addr.wrapping_sub(u64::from(RAM_BASE));
        if addr < u64::from(RAM_BASE) || off + len > u64::from(RAM_SIZE) {
            return Err(LoadError::OutsideRam { addr, len });
        }
        out.push(Segment {
            off: off as usize,
            data,
            exec: ph.p_flags(endian) & object::elf::PF_X != 0,
        });
    }
    Ok(out)
}
