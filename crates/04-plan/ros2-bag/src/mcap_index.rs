//! Random access to the messages of an MCAP file through its index: the summary's chunk indexes
//! and each chunk's message indexes say where every message is, so a message in an uncompressed
//! chunk (rosbag2's default: chunked, no compression) is one positional read, from any thread.
//!
//! Pass 1 of an import needs only the image stamps, a few bytes at the head of each image: read
//! this way it reads those heads and the TF messages, not the 1 MB of pixels of every frame (the
//! linear reader copies the whole file through its buffer). Pass 2 reads each chosen frame where
//! it is, on the worker that decodes it. A file this cannot serve (no summary or chunk index, a
//! compressed chunk, a chunk without message indexes) is read linearly (`storage`).

use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use mcap::records::{op, ChunkIndex, Record};

use super::storage::{mcap_record_limit, BagMessage, Location, Position};
use super::BagError;

/// A message record's fixed part: opcode (1), record length (8), channel id (2), sequence (4),
/// log time (8), publish time (8). The data follows.
const MESSAGE_HEAD: usize = 1 + 8 + 2 + 4 + 8 + 8;
/// A chunk record's part before its records: opcode (1), record length (8), start and end time
/// (8 + 8), uncompressed size (8), uncompressed CRC (4), the compression string's length (4), the
/// string, and the records' length (8).
const CHUNK_HEAD_FIXED: usize = 1 + 8 + 8 + 8 + 8 + 4 + 4;

/// What one read of pass 1 takes in: the TF messages recorded between two frames and the next
/// frame's head are one read, not one per message (a 60 s bag has thousands of them).
const WINDOW_BYTES: u64 = 16 << 10;

/// Bytes read ahead from a file, serving the reads that fall inside them.
#[derive(Default)]
struct Window {
    start: u64,
    bytes: Vec<u8>,
}

impl Window {
    /// `len` bytes at `offset`: from the window when they are in it, else read with what
    /// follows (up to [`WINDOW_BYTES`], not past `end`).
    fn get(
        &mut self,
        index: &McapIndex,
        offset: u64,
        len: u64,
        end: u64,
    ) -> Result<&[u8], BagError> {
        let inside = offset >= self.start && offset + len <= self.start + self.bytes.len() as u64;
        if !inside {
            let ahead = WINDOW_BYTES.min(end.saturating_sub(offset));
            self.bytes = index.read(offset, len.max(ahead))?;
            self.start = offset;
        }
        let at = (offset - self.start) as usize;
        Ok(&self.bytes[at..at + len as usize])
    }
}

/// An MCAP file's index, opened for positional reads.
#[derive(Debug)]
pub(super) struct McapIndex {
    path: PathBuf,
    file: File,
    len: u64,
    chunks: Vec<ChunkIndex>,
    /// Channel id → (topic, message encoding).
    channels: HashMap<u16, (String, String)>,
}

impl McapIndex {
    /// The index of `file` from its summary, or `None` when it cannot serve positional reads.
    pub(super) fn open(path: &Path, summary: Option<mcap::Summary>) -> Option<McapIndex> {
        let summary = summary?;
        let usable = !summary.chunk_indexes.is_empty()
            && summary
                .chunk_indexes
                .iter()
                .all(|c| c.compression.is_empty() && !c.message_index_offsets.is_empty());
        if !usable {
            return None;
        }
        let file = File::open(path).ok()?;
        let len = file.metadata().ok()?.len();
        let mut chunks = summary.chunk_indexes;
        chunks.sort_by_key(|c| c.chunk_start_offset);
        let channels = summary
            .channels
            .iter()
            .map(|(id, c)| (*id, (c.topic.clone(), c.message_encoding.clone())))
            .collect();
        Some(McapIndex {
            path: path.to_path_buf(),
            file,
            len,
            chunks,
            channels,
        })
    }

    fn damaged(&self, problem: String) -> BagError {
        BagError::Storage {
            path: self.path.clone(),
            problem: format!("damaged MCAP file: {problem}"),
        }
    }

    /// `len` bytes at `offset` (a message's data at its `Position::Bytes`), which must lie inside
    /// the file: a damaged index otherwise reads past its end or allocates what a broken length
    /// field says.
    pub(super) fn read(&self, offset: u64, len: u64) -> Result<Vec<u8>, BagError> {
        let mut bytes = Vec::new();
        self.read_into(offset, len, &mut bytes)?;
        Ok(bytes)
    }

    /// [`McapIndex::read`] into `bytes`, reusing its memory: a buffer read into again and again
    /// (a frame at a time) is allocated and cleared only when it must grow.
    pub(super) fn read_into(
        &self,
        offset: u64,
        len: u64,
        bytes: &mut Vec<u8>,
    ) -> Result<(), BagError> {
        let end = offset.checked_add(len).filter(|&e| e <= self.len);
        if end.is_none() || len > mcap_record_limit(self.len) as u64 {
            return Err(self.damaged(format!(
                "its index points at {len} bytes at offset {offset}, past the end of the file ({} bytes)",
                self.len
            )));
        }
        let len = len as usize;
        if bytes.len() < len {
            bytes.try_reserve_exact(len - bytes.len()).map_err(|_| {
                super::storage::out_of_memory(&self.path, len as u64, "reading a message")
            })?;
            bytes.resize(len, 0);
        }
        bytes.truncate(len);
        self.file
            .read_exact_at(bytes, offset)
            .map_err(|source| BagError::Read {
                path: self.path.clone(),
                source,
            })
    }

    /// Every message on `topics` in file order, lent to `visit`; of the topics in `heads_only`
    /// only the first `head_bytes` of the data (or all of it, when shorter).
    pub(super) fn for_each(
        &self,
        file_index: usize,
        topics: &[String],
        heads_only: &[String],
        head_bytes: usize,
        visit: &mut dyn FnMut(BagMessage<'_>) -> Result<(), BagError>,
    ) -> Result<(), BagError> {
        let wanted: HashMap<u16, (&str, bool)> = self
            .channels
            .iter()
            .filter(|(_, (topic, _))| topics.contains(topic))
            .map(|(id, (topic, _))| (*id, (topic.as_str(), heads_only.contains(topic))))
            .collect();
        for (id, (topic, encoding)) in &self.channels {
            if wanted.contains_key(id) && encoding != "cdr" {
                return Err(BagError::Storage {
                    path: self.path.clone(),
                    problem: format!("topic `{topic}` is encoded as `{encoding}`, expected cdr"),
                });
            }
        }
        for chunk in &self.chunks {
            let records_start = self.records_start(chunk)?;
            // The wanted channels' message indexes sit together after the chunk.
            let mut messages: Vec<(u64, u16)> = Vec::new();
            for (channel, at) in &chunk.message_index_offsets {
                if wanted.contains_key(channel) {
                    for entry in self.message_index(*channel, *at)? {
                        messages.push((entry.offset, *channel));
                    }
                }
            }
            messages.sort_unstable();
            let chunk_end = chunk.chunk_start_offset + chunk.chunk_length;
            let mut window = Window::default();
            for (offset, channel) in messages {
                let (topic, head_only) = wanted[&channel];
                let record = records_start + offset;
                let head = window.get(self, record, MESSAGE_HEAD as u64, chunk_end)?;
                let field = |at: usize, n: usize| &head[at..at + n];
                let le64 = |at| u64::from_le_bytes(field(at, 8).try_into().expect("8 bytes"));
                let record_len = le64(1);
                let channel_in_record =
                    u16::from_le_bytes(field(9, 2).try_into().expect("2 bytes"));
                if head[0] != op::MESSAGE
                    || channel_in_record != channel
                    || record_len < (MESSAGE_HEAD - 9) as u64
                {
                    return Err(self.damaged(format!(
                        "the message index of chunk at offset {} points at offset {record}, which holds no message of channel {channel}",
                        chunk.chunk_start_offset
                    )));
                }
                let data_offset = record + MESSAGE_HEAD as u64;
                let data_len = record_len - (MESSAGE_HEAD - 9) as u64;
                if data_offset + data_len > chunk_end {
                    return Err(self.damaged(format!(
                        "a message of {data_len} bytes at offset {record} runs past the end of its chunk"
                    )));
                }
                let read_len = if head_only {
                    data_len.min(head_bytes as u64)
                } else {
                    data_len
                };
                let log_time_ns = i64::try_from(le64(15)).unwrap_or(i64::MAX);
                let data = window.get(self, data_offset, read_len, chunk_end)?;
                visit(BagMessage {
                    topic,
                    log_time_ns,
                    data,
                    location: Location {
                        file: file_index,
                        at: Position::Bytes {
                            offset: data_offset,
                            len: data_len,
                        },
                    },
                })?;
            }
        }
        Ok(())
    }

    /// Where a chunk's records start, read from its header (and checked against its index).
    fn records_start(&self, chunk: &ChunkIndex) -> Result<u64, BagError> {
        let head_len = CHUNK_HEAD_FIXED + chunk.compression.len() + 8;
        let head = self.read(chunk.chunk_start_offset, head_len as u64)?;
        let compression_len = u32::from_le_bytes(
            head[CHUNK_HEAD_FIXED - 4..CHUNK_HEAD_FIXED]
                .try_into()
                .unwrap(),
        );
        if head[0] != op::CHUNK || compression_len as usize != chunk.compression.len() {
            return Err(self.damaged(format!(
                "the chunk index points at offset {}, where no chunk starts",
                chunk.chunk_start_offset
            )));
        }
        Ok(chunk.chunk_start_offset + head_len as u64)
    }

    /// The entries of one channel's message index record at `at`.
    fn message_index(
        &self,
        channel: u16,
        at: u64,
    ) -> Result<Vec<mcap::records::MessageIndexEntry>, BagError> {
        let head = self.read(at, 9)?;
        let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
        let body = self.read(at + 9, len)?;
        match mcap::parse_record(head[0], &body) {
            Ok(Record::MessageIndex(index)) if index.channel_id == channel => Ok(index.records),
            _ => Err(self.damaged(format!(
                "no message index of channel {channel} at offset {at}, where the chunk index says"
            ))),
        }
    }
}
