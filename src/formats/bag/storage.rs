//! The two rosbag2 storage formats: MCAP (`mcap` crate) and sqlite3 `.db3` (`rusqlite`). A bag
//! is a folder holding `metadata.yaml` and its storage files, or one storage file given directly;
//! the format follows from the files' extension (and, for a file of another name, its first
//! bytes). Only the topics asked for are read; messages come back in receive-time order.
//!
//! A damaged file is refused with its name: an MCAP file that ends early (no footer, or a record
//! cut short) and an SQLite file shorter than its header says.

use std::path::{Path, PathBuf};

use super::BagError;

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

/// One message read from a bag: borrowed where the storage reader lends it, owned otherwise (the
/// `mcap` crate's reader and the sqlite3 rows copy every message).
#[derive(Debug, Clone)]
pub struct BagMessage<'a> {
    /// Its topic.
    pub topic: String,
    /// When the recorder received it, ns.
    pub log_time_ns: i64,
    /// The serialised (CDR) message.
    pub data: std::borrow::Cow<'a, [u8]>,
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

/// Memory the import needs besides the bag's bytes (decoded frames, the session run): checked
/// free after the bag is read, so a bag that just fits fails here, clearly, rather than with an
/// abort later.
const HEADROOM_BYTES: usize = 256 << 20;

fn out_of_memory(file: &Path, bytes: u64, what: &str) -> BagError {
    BagError::OutOfMemory {
        path: file.to_path_buf(),
        bytes,
        problem: format!(
            "{what} failed (a memory limit such as `ulimit -v`, or too little free RAM); the import holds the messages it reads in memory (an MCAP bag: the file and a copy of its messages), plus about {} MB: raise the limit, or split the bag (`ros2 bag convert`)",
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
    /// The MCAP files' bytes, read once (empty for sqlite3).
    mcap: Vec<Vec<u8>>,
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
                crate::camera::files::natural_cmp(&a.to_string_lossy(), &b.to_string_lossy())
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
        let mut mcap = Vec::new();
        if format == BagFormat::Mcap {
            for file in &files {
                let bytes = read_file(file)?;
                mcap_check_complete(file, &bytes)?;
                mcap.push(bytes);
            }
            // The `mcap` reader copies every message it yields (and its records into a buffer
            // of its own), with allocations that abort when they fail: room for a copy of the
            // whole file, plus the rest of the import, is checked here instead.
            let total: u64 = mcap.iter().map(|b| b.len() as u64).sum();
            let copies = usize::try_from(total).unwrap_or(usize::MAX);
            let mut probe: Vec<u8> = Vec::new();
            probe
                .try_reserve_exact(copies.saturating_add(HEADROOM_BYTES))
                .map_err(|_| {
                    out_of_memory(
                        path,
                        total,
                        &format!(
                            "the file is in memory, but keeping {} MB free for the copies the MCAP reader makes of its messages and {} MB for the rest of the import",
                            total.div_ceil(1 << 20),
                            HEADROOM_BYTES >> 20
                        ),
                    )
                })?;
        }
        Ok(Bag {
            path: path.to_path_buf(),
            files,
            format,
            mcap,
        })
    }

    /// The storage format.
    pub fn format(&self) -> BagFormat {
        self.format
    }

    /// The topics with their types and message counts, in name order.
    pub fn topics(&self) -> Result<Vec<TopicInfo>, BagError> {
        let mut all: Vec<TopicInfo> = Vec::new();
        for (i, file) in self.files.iter().enumerate() {
            let found = match self.format {
                BagFormat::Mcap => mcap_topics(file, &self.mcap[i])?,
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

    /// Every message on `topics`, in receive-time order.
    pub fn read(&self, topics: &[String]) -> Result<Vec<BagMessage<'_>>, BagError> {
        let mut out = Vec::new();
        for (i, file) in self.files.iter().enumerate() {
            match self.format {
                BagFormat::Mcap => mcap_read(file, &self.mcap[i], topics, &mut out)?,
                BagFormat::Sqlite3 => sqlite_read(file, topics, &mut out)?,
            }
        }
        out.sort_by_key(|m| m.log_time_ns);
        // The messages are in memory; the rest of the import needs room too.
        let mut probe: Vec<u8> = Vec::new();
        probe.try_reserve_exact(HEADROOM_BYTES).map_err(|_| {
            let bytes = self
                .files
                .iter()
                .map(|f| std::fs::metadata(f).map_or(0, |m| m.len()))
                .sum();
            out_of_memory(
                &self.path,
                bytes,
                &format!(
                    "its messages are in memory, but keeping {} MB free for the rest of the import",
                    HEADROOM_BYTES >> 20
                ),
            )
        })?;
        Ok(out)
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

/// The whole file, its buffer reserved fallibly: a file larger than the memory the process may
/// use is an error naming it, not an abort.
fn read_file(file: &Path) -> Result<Vec<u8>, BagError> {
    use std::io::Read;
    let io = |source| BagError::Read {
        path: file.to_path_buf(),
        source,
    };
    let mut f = std::fs::File::open(file).map_err(io)?;
    let len = f.metadata().map_err(io)?.len();
    let mut bytes = Vec::new();
    usize::try_from(len)
        .ok()
        .and_then(|n| bytes.try_reserve_exact(n).ok())
        .ok_or_else(|| {
            out_of_memory(
                file,
                len,
                &format!("allocating {} MB for it", len.div_ceil(1 << 20)),
            )
        })?;
    f.read_to_end(&mut bytes).map_err(io)?;
    Ok(bytes)
}

fn mcap_error(file: &Path, e: mcap::McapError) -> BagError {
    BagError::Storage {
        path: file.to_path_buf(),
        problem: format!("damaged or truncated MCAP file: {e}"),
    }
}

fn mcap_check_complete(file: &Path, bytes: &[u8]) -> Result<(), BagError> {
    if bytes.len() < 2 * MCAP_MAGIC.len() || !bytes.ends_with(MCAP_MAGIC) {
        return Err(BagError::Storage {
            path: file.to_path_buf(),
            problem: format!(
                "truncated MCAP file: {} bytes without the closing magic (the recording did not finish or the copy is cut short)",
                bytes.len()
            ),
        });
    }
    Ok(())
}

fn mcap_type(channel: &mcap::Channel<'_>) -> String {
    channel
        .schema
        .as_ref()
        .map(|s| s.name.clone())
        .unwrap_or_else(|| "(no schema)".into())
}

fn mcap_topics(file: &Path, bytes: &[u8]) -> Result<Vec<TopicInfo>, BagError> {
    let mut topics: Vec<TopicInfo> = Vec::new();
    // The summary section lists channels and counts without reading every message.
    if let Ok(Some(summary)) = mcap::Summary::read(bytes) {
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
    for message in mcap::MessageStream::new(bytes).map_err(|e| mcap_error(file, e))? {
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

fn mcap_read<'a>(
    file: &Path,
    bytes: &'a [u8],
    topics: &[String],
    out: &mut Vec<BagMessage<'a>>,
) -> Result<(), BagError> {
    for message in mcap::MessageStream::new(bytes).map_err(|e| mcap_error(file, e))? {
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
        out.try_reserve(1)
            .map_err(|_| out_of_memory(file, 0, "growing the list of messages"))?;
        out.push(BagMessage {
            topic: message.channel.topic.clone(),
            log_time_ns: i64::try_from(message.log_time).unwrap_or(i64::MAX),
            data: message.data,
        });
    }
    Ok(())
}

fn sqlite_error(file: &Path, e: rusqlite::Error) -> BagError {
    BagError::Storage {
        path: file.to_path_buf(),
        problem: format!("damaged sqlite3 bag: {e}"),
    }
}

/// Opens a `.db3` read-only after checking its length against the page count in its header
/// (a truncated copy otherwise reads as a bag with fewer messages).
fn sqlite_open(file: &Path) -> Result<rusqlite::Connection, BagError> {
    let bytes_len = std::fs::metadata(file)
        .map_err(|source| BagError::Read {
            path: file.to_path_buf(),
            source,
        })?
        .len();
    let mut header = [0u8; 100];
    {
        use std::io::Read;
        let n = std::fs::File::open(file)
            .and_then(|mut f| f.read(&mut header))
            .map_err(|source| BagError::Read {
                path: file.to_path_buf(),
                source,
            })?;
        if n < 100 || !header.starts_with(SQLITE_MAGIC) {
            return Err(BagError::Storage {
                path: file.to_path_buf(),
                problem: format!("not an sqlite3 file ({n} bytes of header)"),
            });
        }
    }
    let page_size = match u16::from_be_bytes([header[16], header[17]]) {
        1 => 65536u64,
        p => u64::from(p),
    };
    let pages = u64::from(u32::from_be_bytes([
        header[28], header[29], header[30], header[31],
    ]));
    let counter = &header[24..28];
    let valid_for = &header[92..96];
    if pages > 0 && counter == valid_for && bytes_len < pages * page_size {
        return Err(BagError::Storage {
            path: file.to_path_buf(),
            problem: format!(
                "truncated sqlite3 file: {bytes_len} bytes, its header says {pages} pages of {page_size} bytes"
            ),
        });
    }
    rusqlite::Connection::open_with_flags(
        file,
        rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| sqlite_error(file, e))
}

fn sqlite_topics(file: &Path) -> Result<Vec<TopicInfo>, BagError> {
    let db = sqlite_open(file)?;
    let mut statement = db
        .prepare(
            "SELECT t.name, t.type, (SELECT COUNT(*) FROM messages m WHERE m.topic_id = t.id) FROM topics t",
        )
        .map_err(|e| sqlite_error(file, e))?;
    let rows = statement
        .query_map([], |row| {
            Ok(TopicInfo {
                name: row.get(0)?,
                type_name: row.get(1)?,
                count: row.get::<_, i64>(2)? as usize,
            })
        })
        .map_err(|e| sqlite_error(file, e))?;
    rows.collect::<Result<Vec<_>, _>>()
        .map_err(|e| sqlite_error(file, e))
}

fn sqlite_read(file: &Path, topics: &[String], out: &mut Vec<BagMessage>) -> Result<(), BagError> {
    let db = sqlite_open(file)?;
    let mut ids: Vec<(i64, String, String)> = Vec::new();
    {
        let mut statement = db
            .prepare("SELECT id, name, serialization_format FROM topics")
            .map_err(|e| sqlite_error(file, e))?;
        let rows = statement
            .query_map([], |row| Ok((row.get(0)?, row.get(1)?, row.get(2)?)))
            .map_err(|e| sqlite_error(file, e))?;
        for row in rows {
            let (id, name, format): (i64, String, String) =
                row.map_err(|e| sqlite_error(file, e))?;
            if topics.contains(&name) {
                if format != "cdr" {
                    return Err(BagError::Storage {
                        path: file.to_path_buf(),
                        problem: format!(
                            "topic `{name}` is serialised as `{format}`, expected cdr"
                        ),
                    });
                }
                ids.push((id, name, format));
            }
        }
    }
    let mut statement = db
        .prepare("SELECT timestamp, data FROM messages WHERE topic_id = ?1 ORDER BY timestamp")
        .map_err(|e| sqlite_error(file, e))?;
    let mut held: u64 = 0;
    for (id, name, _) in ids {
        let mut rows = statement.query([id]).map_err(|e| sqlite_error(file, e))?;
        while let Some(row) = rows.next().map_err(|e| sqlite_error(file, e))? {
            let log_time_ns: i64 = row.get(0).map_err(|e| sqlite_error(file, e))?;
            let blob = row
                .get_ref(1)
                .and_then(|v| v.as_blob().map_err(Into::into))
                .map_err(|e| sqlite_error(file, e))?;
            // Copied into a buffer reserved fallibly: rows that do not fit in memory are an
            // error naming the file, not an abort.
            let mut data = Vec::new();
            data.try_reserve_exact(blob.len())
                .and_then(|()| out.try_reserve(1))
                .map_err(|_| {
                    let bytes = std::fs::metadata(file).map_or(0, |m| m.len());
                    out_of_memory(
                        file,
                        bytes,
                        &format!(
                            "holding the messages of `{name}` ({} MB read so far)",
                            held.div_ceil(1 << 20)
                        ),
                    )
                })?;
            data.extend_from_slice(blob);
            held += data.len() as u64;
            out.push(BagMessage {
                topic: name.clone(),
                log_time_ns,
                data: std::borrow::Cow::Owned(data),
            });
        }
    }
    Ok(())
}
