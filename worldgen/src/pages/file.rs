//! The page file: one raster layer as fixed square pages.
//!
//! Layout (little-endian):
//!
//! ```text
//! header, 64 bytes   magic `TVS-PAGE`, version u32, sample kind u32 (1 = f32, 2 = u8),
//!                    width u32, height u32 (samples), page side u32 (samples),
//!                    pages per row u32, page rows u32, source key u64, zeros,
//!                    CRC-32 of the bytes before it u32 (at byte 60)
//! page i             at 64 + i * stride, i = row * pages_per_row + column, rows from the south:
//!                    side x side samples, row-major, row 0 = south; past the raster's east or
//!                    north edge each row repeats its last sample and the last row repeats;
//!                    then CRC-32 of (i as u32, samples) u32 and the mark `PAG1`
//! ```
//!
//! Every page has a fixed size and place, so a page's bytes depend only on the raster and its
//! index: baking pages in any order or subset, on one machine or many, writes the same file. A
//! page not baked yet is a hole of zeros (no mark). The checksum covers the page's index, so a
//! page copied to another slot is caught too.

use super::PageError;
use crate::Grid;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"TVS-PAGE";
/// Version of the page file layout.
pub const FORMAT_VERSION: u32 = 1;
/// Header bytes before the first page.
pub const HEADER_BYTES: u64 = 64;
const PAGE_MARK: [u8; 4] = *b"PAG1";
/// Largest page side in samples.
pub const MAX_PAGE_SIDE: u32 = 4096;
/// Largest raster side in samples a page file holds (a 1,000 km world at 1 m).
pub const MAX_SIDE: u32 = 1 << 20;

/// What one sample is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleKind {
    F32,
    U8,
}

impl SampleKind {
    pub fn bytes(self) -> usize {
        match self {
            SampleKind::F32 => 4,
            SampleKind::U8 => 1,
        }
    }

    fn code(self) -> u32 {
        match self {
            SampleKind::F32 => 1,
            SampleKind::U8 => 2,
        }
    }

    fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(SampleKind::F32),
            2 => Some(SampleKind::U8),
            _ => None,
        }
    }
}

/// A sample type a page file can hold.
pub trait Sample: Copy + Default + Send + Sync + 'static {
    const KIND: SampleKind;
    /// Appends the sample's little-endian bytes.
    fn put(self, out: &mut Vec<u8>);
    /// The sample from its little-endian bytes (`bytes.len() == KIND.bytes()`).
    fn take(bytes: &[u8]) -> Self;
}

impl Sample for f32 {
    const KIND: SampleKind = SampleKind::F32;
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn take(bytes: &[u8]) -> Self {
        f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])
    }
}

impl Sample for u8 {
    const KIND: SampleKind = SampleKind::U8;
    fn put(self, out: &mut Vec<u8>) {
        out.push(self);
    }
    fn take(bytes: &[u8]) -> Self {
        bytes[0]
    }
}

/// The shape of a paged raster.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageLayout {
    pub kind: SampleKind,
    /// Raster width and height in samples.
    pub width: u32,
    pub height: u32,
    /// Samples per page side.
    pub page_side: u32,
}

impl PageLayout {
    /// A layout, or what is wrong with it.
    pub fn new(kind: SampleKind, width: u32, height: u32, page_side: u32) -> Result<Self, String> {
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(format!(
                "raster of {width}x{height} samples: each side must be 1..={MAX_SIDE}"
            ));
        }
        if page_side == 0 || page_side > MAX_PAGE_SIDE {
            return Err(format!(
                "page side {page_side}: must be 1..={MAX_PAGE_SIDE} samples"
            ));
        }
        Ok(Self {
            kind,
            width,
            height,
            page_side,
        })
    }

    pub fn pages_per_row(&self) -> u32 {
        self.width.div_ceil(self.page_side)
    }

    pub fn page_rows(&self) -> u32 {
        self.height.div_ceil(self.page_side)
    }

    pub fn page_count(&self) -> u32 {
        self.pages_per_row() * self.page_rows()
    }

    /// Samples in one page.
    pub fn page_samples(&self) -> usize {
        self.page_side as usize * self.page_side as usize
    }

    /// Bytes of one page in the file: samples, checksum, mark.
    pub fn page_stride_bytes(&self) -> u64 {
        (self.page_samples() * self.kind.bytes()) as u64 + 8
    }

    /// Length of a complete page file.
    pub fn file_bytes(&self) -> u64 {
        HEADER_BYTES + u64::from(self.page_count()) * self.page_stride_bytes()
    }

    /// Index of the page in `column`, `row` (from the south-west).
    pub fn index(&self, column: u32, row: u32) -> u32 {
        row * self.pages_per_row() + column
    }

    /// Column and row of page `index`.
    pub fn column_row(&self, index: u32) -> (u32, u32) {
        (index % self.pages_per_row(), index / self.pages_per_row())
    }

    fn page_offset(&self, index: u32) -> u64 {
        HEADER_BYTES + u64::from(index) * self.page_stride_bytes()
    }
}

fn header_bytes(layout: &PageLayout, key: u64) -> [u8; HEADER_BYTES as usize] {
    let mut h = [0u8; HEADER_BYTES as usize];
    h[0..8].copy_from_slice(MAGIC);
    let fields = [
        FORMAT_VERSION,
        layout.kind.code(),
        layout.width,
        layout.height,
        layout.page_side,
        layout.pages_per_row(),
        layout.page_rows(),
    ];
    for (i, v) in fields.iter().enumerate() {
        h[8 + 4 * i..12 + 4 * i].copy_from_slice(&v.to_le_bytes());
    }
    h[36..44].copy_from_slice(&key.to_le_bytes());
    let crc = crc32fast::hash(&h[0..60]);
    h[60..64].copy_from_slice(&crc.to_le_bytes());
    h
}

fn parse_header(
    h: &[u8; HEADER_BYTES as usize],
    path: &Path,
) -> Result<(PageLayout, u64), PageError> {
    let bad = |problem: String| PageError::Header {
        path: path.to_path_buf(),
        problem,
    };
    if &h[0..8] != MAGIC {
        return Err(bad("it does not start with `TVS-PAGE`".into()));
    }
    let word = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
    if word(60) != crc32fast::hash(&h[0..60]) {
        return Err(bad("the header does not match its checksum".into()));
    }
    if word(8) != FORMAT_VERSION {
        return Err(bad(format!(
            "version {} (this build reads {FORMAT_VERSION}); bake the map again with `worldgen bake`",
            word(8)
        )));
    }
    let kind = SampleKind::from_code(word(12))
        .ok_or_else(|| bad(format!("sample kind {} is unknown", word(12))))?;
    let layout = PageLayout::new(kind, word(16), word(20), word(24)).map_err(bad)?;
    if word(28) != layout.pages_per_row() || word(32) != layout.page_rows() {
        return Err(bad(format!(
            "{}x{} pages do not tile {}x{} samples in pages of {}",
            word(28),
            word(32),
            layout.width,
            layout.height,
            layout.page_side
        )));
    }
    let mut key = [0u8; 8];
    key.copy_from_slice(&h[36..44]);
    Ok((layout, u64::from_le_bytes(key)))
}

/// The bytes of page (`column`, `row`) of `raster` as stored: samples, checksum, mark.
pub fn page_bytes<T: Sample>(
    layout: &PageLayout,
    raster: &Grid<T>,
    column: u32,
    row: u32,
) -> Vec<u8> {
    let side = layout.page_side as usize;
    let mut out = Vec::with_capacity(layout.page_stride_bytes() as usize);
    let index = layout.index(column, row);
    out.extend_from_slice(&index.to_le_bytes());
    let (x0, y0) = (column as usize * side, row as usize * side);
    for y in y0..y0 + side {
        let yc = y.min(raster.height() - 1);
        for x in x0..x0 + side {
            raster.get(x.min(raster.width() - 1), yc).put(&mut out);
        }
    }
    let crc = crc32fast::hash(&out);
    out.drain(0..4);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&PAGE_MARK);
    out
}

/// A page file opened for reading: header checked, length checked against it.
#[derive(Debug)]
pub struct PageFile {
    path: PathBuf,
    file: File,
    layout: PageLayout,
    key: u64,
}

impl PageFile {
    /// Opens `path`, checking the header and that the file holds every page it describes.
    pub fn open(path: &Path) -> Result<Self, PageError> {
        let io = |action, source| PageError::Io {
            path: path.to_path_buf(),
            action,
            source,
        };
        let file = File::open(path).map_err(|e| io("open the page file", e))?;
        let found = file
            .metadata()
            .map_err(|e| io("read the page file's size", e))?
            .len();
        if found < HEADER_BYTES {
            return Err(PageError::Length {
                path: path.to_path_buf(),
                found,
                expected: HEADER_BYTES,
            });
        }
        let mut h = [0u8; HEADER_BYTES as usize];
        file.read_exact_at(&mut h, 0)
            .map_err(|e| io("read the page file's header", e))?;
        let (layout, key) = parse_header(&h, path)?;
        if found != layout.file_bytes() {
            return Err(PageError::Length {
                path: path.to_path_buf(),
                found,
                expected: layout.file_bytes(),
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            layout,
            key,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn layout(&self) -> PageLayout {
        self.layout
    }

    /// The key of the source the pages were baked from (see [`super::bake`]).
    pub fn key(&self) -> u64 {
        self.key
    }

    /// Every page, checked, assembled into the whole raster (bands of pages read on all
    /// cores).
    pub fn read_all<T: Sample>(&self) -> Result<Grid<T>, PageError> {
        let l = self.layout();
        let (width, height, side) = (l.width as usize, l.height as usize, l.page_side as usize);
        let mut data = vec![T::default(); width * height];
        let mut bands: Vec<(u32, &mut [T])> = data
            .chunks_mut(width * side)
            .enumerate()
            .map(|(r, band)| (r as u32, band))
            .collect();
        let threads = crate::par::thread_count(0).min(bands.len()).max(1);
        let per_thread = bands.len().div_ceil(threads);
        let result: Result<(), PageError> = std::thread::scope(|scope| {
            let jobs: Vec<_> = bands
                .chunks_mut(per_thread)
                .map(|group| {
                    scope.spawn(move || {
                        for (row, band) in group.iter_mut() {
                            for column in 0..l.pages_per_row() {
                                let page = self.read_page::<T>(column, *row)?;
                                let x0 = column as usize * side;
                                let n = side.min(width - x0);
                                for (y, out) in band.chunks_exact_mut(width).enumerate() {
                                    out[x0..x0 + n].copy_from_slice(&page[y * side..y * side + n]);
                                }
                            }
                        }
                        Ok(())
                    })
                })
                .collect();
            jobs.into_iter()
                .try_for_each(|j| j.join().expect("a page band reader panicked"))
        });
        result?;
        Ok(Grid::from_vec(width, height, data).expect("sized by the layout"))
    }

    /// Reads page (`column`, `row`) and checks its mark and checksum.
    pub fn read_page<T: Sample>(&self, column: u32, row: u32) -> Result<Vec<T>, PageError> {
        let l = &self.layout;
        if T::KIND != l.kind || column >= l.pages_per_row() || row >= l.page_rows() {
            return Err(PageError::Request {
                path: self.path.clone(),
                problem: format!(
                    "page ({column}, {row}) of {:?} samples asked of a file of {}x{} pages of {:?}",
                    T::KIND,
                    l.pages_per_row(),
                    l.page_rows(),
                    l.kind
                ),
            });
        }
        let index = l.index(column, row);
        let mut buf = vec![0u8; l.page_stride_bytes() as usize];
        self.file
            .read_exact_at(&mut buf, l.page_offset(index))
            .map_err(self.page_io(column, row))?;
        let n = buf.len();
        let stored_crc = u32::from_le_bytes([buf[n - 8], buf[n - 7], buf[n - 6], buf[n - 5]]);
        if buf[n - 4..] != PAGE_MARK {
            if buf.iter().all(|&b| b == 0) {
                return Err(PageError::NotBaked {
                    path: self.path.clone(),
                    column,
                    row,
                });
            }
            return Err(PageError::Checksum {
                path: self.path.clone(),
                column,
                row,
            });
        }
        let samples = &buf[..n - 8];
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&index.to_le_bytes());
        hasher.update(samples);
        if hasher.finalize() != stored_crc {
            return Err(PageError::Checksum {
                path: self.path.clone(),
                column,
                row,
            });
        }
        Ok(samples.chunks_exact(l.kind.bytes()).map(T::take).collect())
    }

    /// The error of a failed read of page (`column`, `row`).
    fn page_io(&self, column: u32, row: u32) -> impl FnOnce(std::io::Error) -> PageError + '_ {
        move |source| PageError::PageIo {
            path: self.path.clone(),
            column,
            row,
            source,
        }
    }

    /// Whether page `index` carries its mark (baked), without checking its checksum.
    pub fn is_baked(&self, index: u32) -> Result<bool, PageError> {
        let l = &self.layout;
        let mut mark = [0u8; 4];
        let at = l.page_offset(index) + l.page_stride_bytes() - 4;
        let (column, row) = l.column_row(index);
        self.file
            .read_exact_at(&mut mark, at)
            .map_err(self.page_io(column, row))?;
        Ok(mark == PAGE_MARK)
    }
}

/// A page file being baked: created at its full length (pages not written yet are holes), or
/// continued when it exists with the same layout and key.
#[derive(Debug)]
pub struct PageWriter {
    path: PathBuf,
    file: File,
    layout: PageLayout,
}

impl PageWriter {
    /// Creates `path` for `layout` and `key`, or continues it if it already describes them.
    /// Bakes of several processes may start at once: the file is made whole (length and header)
    /// under a name of this process's own, then linked into place, which fails if another
    /// process was first; that file is then continued.
    pub fn create_or_continue(
        path: &Path,
        layout: PageLayout,
        key: u64,
    ) -> Result<Self, PageError> {
        let io = |action, source| PageError::Io {
            path: path.to_path_buf(),
            action,
            source,
        };
        if !path.exists() {
            let own = path.with_extension(format!("new-{}", std::process::id()));
            let made = (|| {
                let file = std::fs::OpenOptions::new()
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&own)?;
                file.set_len(layout.file_bytes())?;
                file.write_all_at(&header_bytes(&layout, key), 0)?;
                file.sync_all()?;
                match std::fs::hard_link(&own, path) {
                    Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => Err(e),
                    _ => Ok(()),
                }
            })();
            let _ = std::fs::remove_file(&own);
            made.map_err(|e| io("create the page file", e))?;
        }
        let existing = PageFile::open(path)?;
        if existing.layout != layout || existing.key != key {
            return Err(PageError::Header {
                path: path.to_path_buf(),
                problem: "an unfinished bake of another layout or another map is in the way; remove it or finish that bake".into(),
            });
        }
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| io("open the page file for writing", e))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            layout,
        })
    }

    pub fn layout(&self) -> PageLayout {
        self.layout
    }

    /// Writes page (`column`, `row`) of `raster`.
    pub fn write_page<T: Sample>(
        &self,
        raster: &Grid<T>,
        column: u32,
        row: u32,
    ) -> Result<(), PageError> {
        let bytes = page_bytes(&self.layout, raster, column, row);
        let index = self.layout.index(column, row);
        self.file
            .write_all_at(&bytes, self.layout.page_offset(index))
            .map_err(|source| PageError::PageIo {
                path: self.path.clone(),
                column,
                row,
                source,
            })
    }

    /// Flushes the file to disk.
    pub fn sync(&self) -> Result<(), PageError> {
        self.file.sync_all().map_err(|source| PageError::Io {
            path: self.path.clone(),
            action: "flush the page file to disk",
            source,
        })
    }
}
