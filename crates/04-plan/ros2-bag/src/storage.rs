//! The two rosbag2 storage formats: MCAP (`mcap` crate) and sqlite3 `.db3` (`rusqlite`). A bag
//! is a folder holding `metadata.yaml` and its storage files, or one storage file given directly;
//! the format follows from the files' extension (and, for a file of another name, its first
//! bytes). Only the topics asked for are read.
//!
//! Nothing holds the whole bag: [`Bag::for_each`] streams the messages of the topics asked for
//! (MCAP with uncompressed chunks through its index, `mcap_index`, reading only the heads of the
//! image messages; other MCAP files chunk by chunk through a buffered reader; sqlite3 row by row,
//! `sqlite`), lending each message to the caller and dropping it before the next, with its
//! [`Location`]; [`MessageAt`] reads one message again from its location (the frames chosen, in a
//! second pass), and [`Bag::read_direct`] one of an indexed file from any thread.
//!
//! A damaged file is refused with its name: an MCAP file that ends early (no footer, or a record
//! cut short) and an SQLite file shorter than its header says.

use std::path::{Path, PathBuf};

use super::mcap_index::McapIndex;
use super::BagError;
use sqlite::{sqlite_error, sqlite_for_each, sqlite_open, sqlite_topics};

mod sqlite;

/// Which storage a bag uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagFormat {
    /// MCAP (`.mcap`), the default since ROS 2 Iron.
    Mcap,
    /// sqlite3 (`.db3`), the default before.
    Sqlite3,
}

impl std::fmt::Display for BagFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            BagFormat::Mcap => "mcap",
            BagFormat::Sqlite3 => "sqlite3",
        })
    }
}

/// A topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// `/tf`, `/camera/image_raw`, ...
    pub name: String,
    /// `tf2_msgs/msg/TFMessage`, ...
    pub type_name: String,
    /// Messages on it.
    pub count: usize,
}

/// Where a message is in a bag, to read it again: its storage file and its place in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Location {
    /// Index of the storage file in the bag.
    pub file: usize,
    /// Where in that file.
    pub at: Position,
}

impl Location {
    /// Whether [`Bag::read_direct`] reads it (from any thread).
    pub fn direct(&self) -> bool {
        matches!(self.at, Position::Bytes { .. })
    }
}

/// A message's place in its storage file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Position {
    /// MCAP read linearly: 0-based position among all messages of the file, in file order.
    Nth(u64),
    /// MCAP through its index (`mcap_index`): the message's data, where it is in the file. Read
    /// with one positional read, from any thread ([`Bag::read_direct`]).
    Bytes {
        /// Offset of the data in the file.
        offset: u64,
        /// Its length.
        len: u64,
    },
    /// sqlite3: the row id.
    Row(i64),
}

/// One message read from a bag, lent for the time of a [`Bag::for_each`] callback.
#[derive(Debug, Clone, Copy)]
pub struct BagMessage<'m> {
    /// Its topic.
    pub topic: &'m str,
    /// When the recorder received it, ns.
    pub log_time_ns: i64,
    /// The serialised (CDR) message; of a topic read for its head only (see [`Bag::for_each`]),
    /// its first bytes.
    pub data: &'m [u8],
    /// Where it is, to read it again.
    pub location: Location,
}

/// Storage files a bag folder's `metadata.yaml` names outside the folder (absolute, or up
/// through `..`). They are not read: a bag is its folder's own storage files.
#[derive(Debug, Clone, PartialEq)]
pub struct FilesOutside {
    /// The `metadata.yaml`.
    pub metadata: PathBuf,
    /// The paths of `relative_file_paths` that leave the folder, as written.
    pub paths: Vec<String>,
}

impl std::fmt::Display for FilesOutside {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let paths: Vec<String> = self.paths.iter().map(|p| format!("`{p}`")).collect();
        write!(
            f,
            "{}: relative_file_paths names {} outside the bag folder; not read (the storage files in the folder are); expected paths inside the folder",
            self.metadata.display(),
            paths.join(", ")
        )
    }
}

/// The paths of `folder/metadata.yaml`'s `relative_file_paths` that leave the folder, if any.
/// A metadata file that does not parse, or lacks the list, names none: the storage files are
/// found in the folder, not through it.
fn files_outside(folder: &Path) -> Option<FilesOutside> {
    let metadata = folder.join("metadata.yaml");
    let text = std::fs::read_to_string(&metadata).ok()?;
    let yaml: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).ok()?;
    let listed = yaml
        .get("rosbag2_bagfile_information")?
        .get("relative_file_paths")?
        .as_sequence()?;
    let paths: Vec<String> = listed
        .iter()
        .filter_map(|p| p.as_str())
        .filter(|p| leaves_folder(Path::new(p)))
        .map(String::from)
        .collect();
    (!paths.is_empty()).then_some(FilesOutside { metadata, paths })
}

/// Whether `path`, taken from inside a folder, ends outside it (written out, not resolved).
fn leaves_folder(path: &Path) -> bool {
    use std::path::Component;
    let mut depth = 0usize;
    for part in path.components() {
        match part {
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
            Component::ParentDir if depth > 0 => depth -= 1,
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => return true,
        }
    }
    false
}

/// Rows of an sqlite3 bag's `messages` table whose `topic_id` is in no row of `topics`.
#[derive(Debug, Clone, PartialEq)]
pub struct UnknownTopicRows {
    /// The `.db3` file.
    pub file: PathBuf,
    /// Those rows.
    pub rows: usize,
    /// All rows of `messages`.
    pub total: usize,
    /// The unknown topic ids with their row counts, in id order.
    pub ids: Vec<(i64, usize)>,
}

/// The share of a file's rows with an unknown topic above which the bag is refused as damaged:
/// a few orphan rows are what a crash mid-write or a tool that dropped a topic leaves; more mean
/// `topics` and `messages` disagree, and the lost rows may be the frames or the TF the
/// calibration needs.
pub const UNKNOWN_TOPIC_ROWS_REFUSED: f64 = 0.05;

impl UnknownTopicRows {
    /// `rows / total`.
    pub fn fraction(&self) -> f64 {
        self.rows as f64 / self.total.max(1) as f64
    }
}

impl std::fmt::Display for UnknownTopicRows {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ids: Vec<String> = self
            .ids
            .iter()
            .map(|(id, n)| format!("{id} ({n} rows)"))
            .collect();
        write!(
            f,
            "{}: {} of {} rows ({:.1} %) of table `messages` name a topic id that is in no row of table `topics` (ids {})",
            self.file.display(),
            self.rows,
            self.total,
            self.fraction() * 100.0,
            ids.join(", ")
        )
    }
}

/// Memory the import needs besides the message being read: the decoded frames it keeps (one grey
/// image per sample), the TF, and the session run. Checked free when the bag is opened, so a
/// limit that cannot fit the import fails there, clearly, rather than with an abort later.
pub const HEADROOM_BYTES: usize = 64 << 20;

pub(super) fn out_of_memory(file: &Path, bytes: u64, what: &str) -> BagError {
    use handeye_core::memory;
    // The limit that was reached, with its figures, when one is set.
    let limit = memory::limits()
        .into_iter()
        .min_by_key(memory::Limit::room)
        .map_or_else(
            || "a memory limit such as `ulimit -v`, or too little free RAM".to_string(),
            |limit| {
                format!(
                    "the limit is {} MB ({}), {} MB of it in use",
                    limit.bytes / memory::MB,
                    limit.kind,
                    limit.in_use.div_ceil(memory::MB)
                )
            },
        );
    BagError::OutOfMemory {
        path: file.to_path_buf(),
        bytes,
        problem: format!(
            "{what} failed ({limit}); the import streams the bag (one message at a time, whatever the bag's size) but needs about {} MB besides, plus its largest message: raise the limit",
            HEADROOM_BYTES >> 20
        ),
    }
}

/// An opened bag: its storage files and format.
#[derive(Debug)]
pub struct Bag {
    /// The bag as given (folder or file).
    path: PathBuf,
    files: Vec<PathBuf>,
    format: BagFormat,
    /// Per storage file, its MCAP index when it serves positional reads (`mcap_index`).
    indexes: Vec<Option<McapIndex>>,
    /// What a folder's `metadata.yaml` names outside it.
    outside: Option<FilesOutside>,
}

const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";

impl Bag {
    /// Opens a bag folder (with `metadata.yaml`) or a single `.mcap`/`.db3` file.
    pub fn open(path: &Path) -> Result<Bag, BagError> {
        let storage = |problem: String| BagError::Storage {
            path: path.to_path_buf(),
            problem,
        };
        let meta = std::fs::metadata(path).map_err(|source| BagError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let files = if meta.is_dir() {
            if !path.join("metadata.yaml").is_file() {
                return Err(storage(
                    "a folder without metadata.yaml is not a rosbag2 bag".into(),
                ));
            }
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|source| BagError::Read {
                    path: path.to_path_buf(),
                    source,
                })?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| {
                    matches!(
                        p.extension().and_then(|e| e.to_str()),
                        Some("mcap" | "db3" | "zstd")
                    )
                })
                .collect();
            files.sort_by(|a, b| {
                handeye_camera::files::natural_cmp(&a.to_string_lossy(), &b.to_string_lossy())
            });
            if files.is_empty() {
                return Err(storage(
                    "no .mcap or .db3 storage file in the bag folder".into(),
                ));
            }
            files
        } else {
            vec![path.to_path_buf()]
        };
        let mut format = None;
        for file in &files {
            let this = file_format(file)?;
            if format.is_some_and(|f| f != this) {
                return Err(storage("the bag mixes MCAP and sqlite3 files".into()));
            }
            format = Some(this);
        }
        let format = format.ok_or_else(|| storage("no storage file".into()))?;
        if format == BagFormat::Mcap {
            for file in &files {
                mcap_check_complete(file)?;
            }
        }
        // The room the import needs besides the message being read (HEADROOM_BYTES), reserved
        // fallibly once: without it, an allocation would abort the process later.
        let mut probe: Vec<u8> = Vec::new();
        probe.try_reserve_exact(HEADROOM_BYTES).map_err(|_| {
            let bytes = files
                .iter()
                .map(|f| std::fs::metadata(f).map_or(0, |m| m.len()))
                .sum();
            out_of_memory(
                path,
                bytes,
                &format!("keeping {} MB free for the import", HEADROOM_BYTES >> 20),
            )
        })?;
        drop(probe);
        let indexes = files
            .iter()
            .map(|file| match format {
                BagFormat::Mcap => {
                    let index = McapIndex::open(file, mcap_summary(file));
                    tracing::debug!(
                        "{}: {}",
                        file.display(),
                        if index.is_some() {
                            "read through its index"
                        } else {
                            "read linearly (no summary or message index, or compressed chunks)"
                        }
                    );
                    index
                }
                BagFormat::Sqlite3 => None,
            })
            .collect();
        Ok(Bag {
            path: path.to_path_buf(),
            outside: meta.is_dir().then(|| files_outside(path)).flatten(),
            files,
            format,
            indexes,
        })
    }

    /// The storage files a folder's `metadata.yaml` names outside the folder (not read).
    pub fn files_outside(&self) -> Option<&FilesOutside> {
        self.outside.as_ref()
    }

    /// The storage format.
    pub fn format(&self) -> BagFormat {
        self.format
    }

    /// The topics with their types and message counts, in name order.
    pub fn topics(&self) -> Result<Vec<TopicInfo>, BagError> {
        let mut all: Vec<TopicInfo> = Vec::new();
        for file in &self.files {
            let found = match self.format {
                BagFormat::Mcap => mcap_topics(file)?,
                BagFormat::Sqlite3 => sqlite_topics(file)?,
            };
            for t in found {
                match all.iter_mut().find(|a| a.name == t.name) {
                    Some(a) => a.count += t.count,
                    None => all.push(t),
                }
            }
        }
        all.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(all)
    }

    /// The rows of each sqlite3 file whose topic is unknown (none for MCAP, whose reader refuses
    /// a message of an unknown channel as damage).
    pub fn unknown_topic_rows(&self) -> Result<Vec<UnknownTopicRows>, BagError> {
        if self.format != BagFormat::Sqlite3 {
            return Ok(Vec::new());
        }
        let mut out = Vec::new();
        for file in &self.files {
            let db = sqlite_open(file)?;
            let total: i64 = db
                .query_row("SELECT COUNT(*) FROM messages", [], |row| row.get(0))
                .map_err(|e| sqlite_error(file, e))?;
            let mut statement = db
                .prepare(
                    "SELECT topic_id, COUNT(*) FROM messages WHERE topic_id NOT IN (SELECT id FROM topics) GROUP BY topic_id ORDER BY topic_id",
                )
                .map_err(|e| sqlite_error(file, e))?;
            let ids = statement
                .query_map([], |row| {
                    Ok((row.get::<_, i64>(0)?, row.get::<_, i64>(1)? as usize))
                })
                .map_err(|e| sqlite_error(file, e))?
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| sqlite_error(file, e))?;
            if !ids.is_empty() {
                out.push(UnknownTopicRows {
                    file: file.clone(),
                    rows: ids.iter().map(|(_, n)| n).sum(),
                    total: total as usize,
                    ids,
                });
            }
        }
        Ok(out)
    }

    /// Every message on `topics`, lent to `visit` one at a time: file by file, each in its storage
    /// order (MCAP: file order; sqlite3: row order). The caller orders them by receive time if it
    /// needs to; only one message is held at a time. Of the topics in `heads_only`, only the first
    /// [`HEAD_BYTES`] of each message are needed (an image's header): an indexed MCAP file and
    /// sqlite3 read just those; an MCAP file read linearly lends the whole message.
    pub fn for_each(
        &self,
        topics: &[String],
        heads_only: &[String],
        mut visit: impl FnMut(BagMessage<'_>) -> Result<(), BagError>,
    ) -> Result<(), BagError> {
        for (i, file) in self.files.iter().enumerate() {
            match (self.format, &self.indexes[i]) {
                (BagFormat::Mcap, Some(index)) => {
                    index.for_each(i, topics, heads_only, HEAD_BYTES, &mut visit)?
                }
                (BagFormat::Mcap, None) => mcap_for_each(i, file, topics, &mut visit)?,
                (BagFormat::Sqlite3, _) => {
                    sqlite_for_each(i, file, topics, heads_only, &mut visit)?
                }
            }
        }
        Ok(())
    }

    /// The message at a [`Location::direct`] location read where it is, from any thread (read
    /// the others through [`MessageAt`]).
    pub fn read_direct(&self, at: Location) -> Result<Vec<u8>, BagError> {
        let mut bytes = Vec::new();
        self.read_direct_into(at, &mut bytes)?;
        Ok(bytes)
    }

    /// [`Bag::read_direct`] into `bytes`, reusing its memory (a worker reading frame after
    /// frame allocates and clears its buffer only when a frame is larger than any before).
    pub fn read_direct_into(&self, at: Location, bytes: &mut Vec<u8>) -> Result<(), BagError> {
        match (at.at, self.indexes.get(at.file).and_then(Option::as_ref)) {
            (Position::Bytes { offset, len }, Some(index)) => index.read_into(offset, len, bytes),
            (position, _) => Err(BagError::Storage {
                path: self.path.clone(),
                problem: format!(
                    "no indexed MCAP file {} to read {position:?} from in the bag",
                    at.file
                ),
            }),
        }
    }

    /// A reader of single messages of `topic` by their [`Location`].
    pub fn message_at(&self, topic: &str) -> MessageAt<'_> {
        MessageAt {
            bag: self,
            topic: topic.to_string(),
            mcap: None,
            recent: std::collections::VecDeque::new(),
            sqlite: None,
            rewinds: 0,
        }
    }
}

/// What [`Bag::for_each`] reads of a message of a `heads_only` topic: a `std_msgs/Header` with
/// any sane frame id, and more than the stamp the import reads.
pub const HEAD_BYTES: usize = 256;

/// The last MCAP messages of the topic read by [`MessageAt`] are kept (their data): a request a
/// few messages back (stamps slightly out of receive order, the same frame again) does not read
/// the file again.
const RECENT_KEPT: usize = 6;

/// Reads single messages of one topic again by their [`Location`] (see [`Bag::message_at`]).
/// MCAP has no cheap random access to a message inside a compressed chunk, so the file is read
/// forward from where the last request left it, keeping the last [`RECENT_KEPT`] messages of the
/// topic; a request further back starts the file again. Requests in file order (the frames in
/// stamp order, as the selection asks for them) read each file once. sqlite3 reads the row.
pub struct MessageAt<'b> {
    bag: &'b Bag,
    topic: String,
    /// The MCAP file being read, the stream, and the position of the next message.
    mcap: Option<(usize, McapStream, u64)>,
    recent: std::collections::VecDeque<(Location, Vec<u8>)>,
    sqlite: Option<(usize, rusqlite::Connection)>,
    rewinds: usize,
}

type McapStream = mcap::io::MessageReader<std::io::BufReader<std::fs::File>>;

impl<'b> MessageAt<'b> {
    /// The bag it reads (for [`Bag::read_direct`] from other threads).
    pub fn bag(&self) -> &'b Bag {
        self.bag
    }

    /// The serialised message at `at` (of this reader's topic).
    pub fn data(&mut self, at: Location) -> Result<Vec<u8>, BagError> {
        if at.direct() {
            return self.bag.read_direct(at);
        }
        let file = self
            .bag
            .files
            .get(at.file)
            .ok_or_else(|| BagError::Storage {
                path: self.bag.path.clone(),
                problem: format!("no storage file {} in the bag", at.file),
            })?;
        match (self.bag.format, at.at) {
            (BagFormat::Sqlite3, Position::Row(row)) => {
                if self.sqlite.as_ref().is_none_or(|(i, _)| *i != at.file) {
                    self.sqlite = Some((at.file, sqlite_open(file)?));
                }
                let (_, db) = self.sqlite.as_ref().expect("opened above");
                db.query_row("SELECT data FROM messages WHERE rowid = ?1", [row], |row| {
                    row.get::<_, Vec<u8>>(0)
                })
                .map_err(|e| sqlite_error(file, e))
            }
            (BagFormat::Mcap, Position::Nth(nth)) => self.mcap_nth(at.file, file, nth),
            (_, position) => Err(BagError::Storage {
                path: file.clone(),
                problem: format!("no message at {position:?} in a {} file", self.bag.format),
            }),
        }
    }

    /// The `nth` message of an MCAP file read linearly (see the type's docs).
    fn mcap_nth(&mut self, index: usize, file: &Path, nth: u64) -> Result<Vec<u8>, BagError> {
        let at = Location {
            file: index,
            at: Position::Nth(nth),
        };
        if let Some(k) = self.recent.iter().position(|(l, _)| *l == at) {
            return Ok(self.recent[k].1.clone());
        }
        let behind = self
            .mcap
            .as_ref()
            .is_none_or(|(i, _, next)| *i != index || *next > nth);
        if behind {
            if self.mcap.is_some() {
                self.rewinds += 1;
            }
            self.recent.clear();
            self.mcap = Some((index, mcap_stream(file)?, 0));
        }
        let (_, stream, next) = self.mcap.as_mut().expect("opened above");
        loop {
            let Some(message) = stream.next() else {
                return Err(BagError::Storage {
                    path: file.to_path_buf(),
                    problem: format!(
                        "damaged MCAP file: message {nth} is gone when read again (the file changed while it was imported?)"
                    ),
                });
            };
            let message = message.map_err(|e| mcap_error(file, e))?;
            let here = Location {
                file: index,
                at: Position::Nth(*next),
            };
            *next += 1;
            if message.channel.topic != self.topic {
                continue;
            }
            let data = message.data.into_owned();
            if self.recent.len() == RECENT_KEPT {
                self.recent.pop_front();
            }
            if here == at {
                self.recent.push_back((here, data.clone()));
                return Ok(data);
            }
            self.recent.push_back((here, data));
        }
    }

    /// How often an MCAP file was started again for a request behind the stream.
    pub fn rewinds(&self) -> usize {
        self.rewinds
    }
}

fn file_format(file: &Path) -> Result<BagFormat, BagError> {
    let storage = |problem: String| BagError::Storage {
        path: file.to_path_buf(),
        problem,
    };
    match file.extension().and_then(|e| e.to_str()) {
        Some("zstd") => {
            return Err(storage(
                "a file-compressed bag: decompress it first (`ros2 bag convert`)".into(),
            ))
        }
        Some("mcap") => return Ok(BagFormat::Mcap),
        Some("db3") => return Ok(BagFormat::Sqlite3),
        _ => {}
    }
    use std::io::Read;
    let mut head = [0u8; 16];
    let n = std::fs::File::open(file)
        .and_then(|mut f| f.read(&mut head))
        .map_err(|source| BagError::Read {
            path: file.to_path_buf(),
            source,
        })?;
    if head[..n].starts_with(MCAP_MAGIC) {
        Ok(BagFormat::Mcap)
    } else if head[..n].starts_with(SQLITE_MAGIC) {
        Ok(BagFormat::Sqlite3)
    } else {
        Err(storage(
            "neither an MCAP nor an sqlite3 file (a rosbag2 bag is a folder with metadata.yaml, or its .mcap/.db3 file)".into(),
        ))
    }
}

/// Reading an MCAP file record by record: no record may be longer than this (a damaged length
/// field would otherwise allocate what it says). Chunks are decompressed as they stream, so the
/// limit is on one record inside them (an image), not on a chunk.
pub(super) fn mcap_record_limit(file_len: u64) -> usize {
    usize::try_from(file_len)
        .unwrap_or(usize::MAX)
        .max(256 << 20)
}

/// An MCAP file's messages, streamed through a buffered reader.
fn mcap_stream(file: &Path) -> Result<McapStream, BagError> {
    let io = |source| BagError::Read {
        path: file.to_path_buf(),
        source,
    };
    let f = std::fs::File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    Ok(mcap::io::MessageReader::new_with_options(
        std::io::BufReader::with_capacity(1 << 20, f),
        mcap::sans_io::LinearReaderOptions::default()
            .with_record_length_limit(mcap_record_limit(len)),
    ))
}

fn mcap_error(file: &Path, e: mcap::McapError) -> BagError {
    BagError::Storage {
        path: file.to_path_buf(),
        problem: format!("damaged or truncated MCAP file: {e}"),
    }
}

/// Refuses a file without the closing magic (a recording that did not finish, a copy cut short)
/// before any of it is read.
fn mcap_check_complete(file: &Path) -> Result<(), BagError> {
    use std::io::{Read, Seek, SeekFrom};
    let io = |source| BagError::Read {
        path: file.to_path_buf(),
        source,
    };
    let mut f = std::fs::File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    let mut tail = [0u8; 8];
    let complete = len >= 2 * MCAP_MAGIC.len() as u64 && {
        f.seek(SeekFrom::End(-(MCAP_MAGIC.len() as i64)))
            .map_err(io)?;
        f.read_exact(&mut tail).map_err(io)?;
        tail == MCAP_MAGIC
    };
    if !complete {
        return Err(BagError::Storage {
            path: file.to_path_buf(),
            problem: format!(
                "truncated MCAP file: {len} bytes without the closing magic (the recording did not finish or the copy is cut short)"
            ),
        });
    }
    Ok(())
}

/// The summary section (channels, message counts), read from the end of the file without the
/// rest; `None` without one (or when it cannot be read: the messages are counted then).
fn mcap_summary(file: &Path) -> Option<mcap::Summary> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    use std::io::{Read, Seek};
    let mut f = std::fs::File::open(file).ok()?;
    let len = f.metadata().ok()?.len();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(len)
            .with_record_length_limit(mcap_record_limit(len)),
    );
    while let Some(event) = reader.next_event() {
        match event.ok()? {
            SummaryReadEvent::ReadRequest(need) => {
                let n = f.read(reader.insert(need)).ok()?;
                reader.notify_read(n);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let at = f.seek(to).ok()?;
                reader.notify_seeked(at);
            }
        }
    }
    reader.finish()
}

fn mcap_type(channel: &mcap::Channel<'_>) -> String {
    channel
        .schema
        .as_ref()
        .map(|s| s.name.clone())
        .unwrap_or_else(|| "(no schema)".into())
}

fn mcap_topics(file: &Path) -> Result<Vec<TopicInfo>, BagError> {
    let mut topics: Vec<TopicInfo> = Vec::new();
    // The summary section lists channels and counts without reading every message.
    if let Some(summary) = mcap_summary(file) {
        let counts = summary
            .stats
            .as_ref()
            .map(|s| s.channel_message_counts.clone());
        for (id, channel) in &summary.channels {
            topics.push(TopicInfo {
                name: channel.topic.clone(),
                type_name: mcap_type(channel),
                count: counts
                    .as_ref()
                    .and_then(|c| c.get(id).copied())
                    .unwrap_or(0) as usize,
            });
        }
        if counts.is_some() {
            return Ok(topics);
        }
        topics.clear();
    }
    for message in mcap_stream(file)? {
        let message = message.map_err(|e| mcap_error(file, e))?;
        match topics.iter_mut().find(|t| t.name == message.channel.topic) {
            Some(t) => t.count += 1,
            None => topics.push(TopicInfo {
                name: message.channel.topic.clone(),
                type_name: mcap_type(&message.channel),
                count: 1,
            }),
        }
    }
    Ok(topics)
}

fn mcap_for_each(
    index: usize,
    file: &Path,
    topics: &[String],
    visit: &mut dyn FnMut(BagMessage<'_>) -> Result<(), BagError>,
) -> Result<(), BagError> {
    for (at, message) in mcap_stream(file)?.enumerate() {
        let message = message.map_err(|e| mcap_error(file, e))?;
        if !topics.contains(&message.channel.topic) {
            continue;
        }
        if message.channel.message_encoding != "cdr" {
            return Err(BagError::Storage {
                path: file.to_path_buf(),
                problem: format!(
                    "topic `{}` is encoded as `{}`, expected cdr",
                    message.channel.topic, message.channel.message_encoding
                ),
            });
        }
        visit(BagMessage {
            topic: &message.channel.topic,
            log_time_ns: i64::try_from(message.log_time).unwrap_or(i64::MAX),
            data: &message.data,
            location: Location {
                file: index,
                at: Position::Nth(at as u64),
            },
        })?;
    }
    Ok(())
}
