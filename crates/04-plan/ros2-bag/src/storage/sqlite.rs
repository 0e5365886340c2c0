//! The sqlite3 storage (`.db3`, rosbag2's default before Iron): opened read-only after its
//! length is checked against its header, its topics, and its messages streamed row by row.

use std::path::Path;

use super::{BagError, BagMessage, Location, Position, TopicInfo, HEAD_BYTES, SQLITE_MAGIC};

pub(super) fn sqlite_error(file: &Path, e: rusqlite::Error) -> BagError {
    BagError::Storage {
        path: file.to_path_buf(),
        problem: format!("damaged sqlite3 bag: {e}"),
    }
}

/// Opens a `.db3` read-only after checking its length against the page count in its header
/// (a truncated copy otherwise reads as a bag with fewer messages).
pub(super) fn sqlite_open(file: &Path) -> Result<rusqlite::Connection, BagError> {
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

pub(super) fn sqlite_topics(file: &Path) -> Result<Vec<TopicInfo>, BagError> {
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

pub(super) fn sqlite_for_each(
    index: usize,
    file: &Path,
    topics: &[String],
    heads_only: &[String],
    visit: &mut dyn FnMut(BagMessage<'_>) -> Result<(), BagError>,
) -> Result<(), BagError> {
    let db = sqlite_open(file)?;
    let mut ids: Vec<(i64, String)> = Vec::new();
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
                ids.push((id, name));
            }
        }
    }
    if ids.is_empty() {
        return Ok(());
    }
    // Row by row in table order (no ORDER BY: sorting would make SQLite hold the rows); each
    // row's blob is lent to `visit` and dropped before the next. Of a `heads_only` topic the row
    // leaves its blob out (the CASE reads the column only for the others) and the head is read
    // through incremental blob I/O: the rest of a frame's pages are not read.
    let list: Vec<String> = ids.iter().map(|(id, _)| id.to_string()).collect();
    let heads: Vec<String> = ids
        .iter()
        .filter(|(_, name)| heads_only.contains(name))
        .map(|(id, _)| id.to_string())
        .collect();
    let mut statement = db
        .prepare(&format!(
            "SELECT rowid, topic_id, timestamp, CASE WHEN topic_id IN ({}) THEN NULL ELSE data END FROM messages WHERE topic_id IN ({})",
            heads.join(", "),
            list.join(", ")
        ))
        .map_err(|e| sqlite_error(file, e))?;
    let mut rows = statement.query([]).map_err(|e| sqlite_error(file, e))?;
    let mut head = Vec::with_capacity(HEAD_BYTES);
    while let Some(row) = rows.next().map_err(|e| sqlite_error(file, e))? {
        let rowid: i64 = row.get(0).map_err(|e| sqlite_error(file, e))?;
        let topic_id: i64 = row.get(1).map_err(|e| sqlite_error(file, e))?;
        let log_time_ns: i64 = row.get(2).map_err(|e| sqlite_error(file, e))?;
        let Some((_, topic)) = ids.iter().find(|(id, _)| *id == topic_id) else {
            continue;
        };
        let data = if heads_only.contains(topic) {
            use std::io::Read;
            let blob = db
                .blob_open(rusqlite::MAIN_DB, "messages", "data", rowid, true)
                .map_err(|e| sqlite_error(file, e))?;
            head.clear();
            blob.take(HEAD_BYTES as u64)
                .read_to_end(&mut head)
                .map_err(|source| BagError::Read {
                    path: file.to_path_buf(),
                    source,
                })?;
            head.as_slice()
        } else {
            row.get_ref(3)
                .and_then(|v| v.as_blob().map_err(Into::into))
                .map_err(|e| sqlite_error(file, e))?
        };
        visit(BagMessage {
            topic,
            log_time_ns,
            data,
            location: Location {
                file: index,
                at: Position::Row(rowid),
            },
        })?;
    }
    Ok(())
}
