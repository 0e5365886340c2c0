//! The storage layer streams: [`Bag::for_each`] lends each message with its location, and
//! [`MessageAt`] reads single messages again by location, in any order, with the right bytes (an
//! MCAP file with compressed chunks read forward, started again only for a request behind the
//! last few kept; one with uncompressed chunks read where the message is, through its index).

use std::collections::BTreeMap;
use std::path::Path;

use super::storage::{Bag, BagFormat, Location, Position, HEAD_BYTES};

/// Message `i`'s payload: its own length and bytes, so a mix-up shows.
fn payload(i: usize) -> Vec<u8> {
    vec![i as u8; 50 + 3 * i]
}

/// An MCAP file with `n` messages alternating between `/image` and `/tf`, chunks of a few
/// messages each, zstd-compressed or not (rosbag2's default).
fn write_mcap(file: &Path, n: usize, compression: Option<mcap::Compression>) {
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(compression)
        .chunk_size(Some(300))
        .create(std::io::BufWriter::new(
            std::fs::File::create(file).unwrap(),
        ))
        .unwrap();
    let image_schema = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let tf_schema = w
        .add_schema("tf2_msgs/msg/TFMessage", "ros2msg", b"")
        .unwrap();
    let image = w
        .add_channel(image_schema, "/image", "cdr", &BTreeMap::new())
        .unwrap();
    let tf = w
        .add_channel(tf_schema, "/tf", "cdr", &BTreeMap::new())
        .unwrap();
    for i in 0..n {
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: if i % 2 == 0 { image } else { tf },
                sequence: i as u32,
                log_time: 1000 + i as u64,
                publish_time: 1000 + i as u64,
            },
            &payload(i),
        )
        .unwrap();
    }
    w.finish().unwrap();
}

/// The same as an sqlite3 `.db3` with rosbag2's tables.
fn write_db3(file: &Path, n: usize) {
    let db = rusqlite::Connection::open(file).unwrap();
    db.execute_batch(
        "CREATE TABLE topics (id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
         CREATE TABLE messages (id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL);
         INSERT INTO topics VALUES (1, '/image', 'sensor_msgs/msg/Image', 'cdr', ''), (2, '/tf', 'tf2_msgs/msg/TFMessage', 'cdr', '');",
    )
    .unwrap();
    for i in 0..n {
        db.execute(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?1, ?2, ?3)",
            rusqlite::params![if i % 2 == 0 { 1 } else { 2 }, 1000 + i as i64, payload(i)],
        )
        .unwrap();
    }
}

/// Every `/image` message through `for_each`: (location, message number from its payload).
fn images(bag: &Bag) -> Vec<(Location, usize)> {
    let mut out = Vec::new();
    bag.for_each(&["/image".to_string()], &[], |m| {
        assert_eq!(m.topic, "/image");
        let i = m.data[0] as usize;
        assert_eq!(m.data, payload(i).as_slice());
        assert_eq!(m.log_time_ns, 1000 + i as i64);
        out.push((m.location, i));
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn messages_stream_and_are_read_again_by_location_in_any_order() {
    let dir = tempfile::tempdir().unwrap();
    let n = 120;
    let (mcap, db3) = (dir.path().join("b.mcap"), dir.path().join("b.db3"));
    write_mcap(&mcap, n, Some(mcap::Compression::Zstd));
    write_db3(&db3, n);
    for (file, format) in [(mcap, BagFormat::Mcap), (db3, BagFormat::Sqlite3)] {
        let bag = Bag::open(&file).unwrap();
        assert_eq!(bag.format(), format);
        assert!(images(&bag).iter().all(|(l, _)| !l.direct()), "{format}");
        let all = images(&bag);
        assert_eq!(
            all.iter().map(|(_, i)| *i).collect::<Vec<_>>(),
            (0..n).step_by(2).collect::<Vec<_>>(),
            "{format}"
        );
        let check = |order: &[usize]| {
            let mut at = bag.message_at("/image");
            for &k in order {
                let (location, i) = all[k];
                assert_eq!(at.data(location).unwrap(), payload(i), "{format}: {k}");
            }
            at.rewinds()
        };
        // In file order, one image in three (the frames a selection keeps): read once.
        let forward: Vec<usize> = (0..all.len()).step_by(3).collect();
        assert_eq!(check(&forward), 0, "{format}");
        // A request a few back (stamps slightly out of receive order) comes from those kept.
        assert_eq!(check(&[10, 12, 9, 11, 13, 8, 20]), 0, "{format}");
        assert_eq!(check(&[10, 10, 11, 10, 15, 10]), 0, "{format}");
        // Further back starts the file again (MCAP; sqlite3 reads the row).
        let expected = usize::from(format == BagFormat::Mcap);
        assert_eq!(check(&[30, 2]), expected, "{format}");
        let backward: Vec<usize> = (0..all.len()).rev().collect();
        check(&backward);
    }
}

#[test]
fn a_location_past_the_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("b.mcap");
    write_mcap(&file, 10, Some(mcap::Compression::Zstd));
    let bag = Bag::open(&file).unwrap();
    let e = bag
        .message_at("/image")
        .data(Location {
            file: 0,
            at: Position::Nth(99),
        })
        .unwrap_err()
        .to_string();
    assert!(e.contains("b.mcap") && e.contains("message 99"), "{e}");
}

#[test]
fn uncompressed_chunks_are_read_where_the_message_is_from_any_thread() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("b.mcap");
    let n = 120;
    write_mcap(&file, n, None);
    let bag = Bag::open(&file).unwrap();
    let all = images(&bag);
    assert_eq!(
        all.iter().map(|(_, i)| *i).collect::<Vec<_>>(),
        (0..n).step_by(2).collect::<Vec<_>>()
    );
    assert!(all.iter().all(|(l, _)| l.direct()));
    // Backwards, from two threads at once: each message's own bytes, no file started again.
    let mut reader = bag.message_at("/image");
    std::thread::scope(|scope| {
        for half in all.chunks(all.len() / 2) {
            let bag = &bag;
            scope.spawn(move || {
                // And into one buffer, read again and again: each message of its own length
                // (they shrink going backwards, then the longest is read once more).
                let mut buffer = Vec::new();
                for (location, i) in half.iter().rev().chain(half.last()) {
                    assert_eq!(bag.read_direct(*location).unwrap(), payload(*i));
                    bag.read_direct_into(*location, &mut buffer).unwrap();
                    assert_eq!(buffer, payload(*i));
                }
            });
        }
    });
    for (location, i) in all.iter().rev() {
        assert_eq!(reader.data(*location).unwrap(), payload(*i));
    }
    assert_eq!(reader.rewinds(), 0);
    assert_heads_only_read(&bag, n);
    let db3 = dir.path().join("b.db3");
    write_db3(&db3, n);
    assert_heads_only_read(&Bag::open(&db3).unwrap(), n);
}

/// A topic read for its heads only lends its first HEAD_BYTES; the others whole.
fn assert_heads_only_read(bag: &Bag, n: usize) {
    let mut seen = 0;
    bag.for_each(&["/image".into(), "/tf".into()], &["/image".into()], |m| {
        let i = m.data[0] as usize;
        let whole = payload(i);
        match m.topic {
            "/image" => assert_eq!(m.data, &whole[..whole.len().min(HEAD_BYTES)]),
            _ => assert_eq!(m.data, whole.as_slice()),
        }
        seen += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(seen, n);
}

#[test]
fn an_index_that_points_elsewhere_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("b.mcap");
    write_mcap(&file, 40, None);
    let bag = Bag::open(&file).unwrap();
    let (first, _) = images(&bag)[0];
    let Position::Bytes { offset, len } = first.at else {
        panic!("{first:?} is not read where it is");
    };
    // The message's record head overwritten: the index now points at no message.
    let mut bytes = std::fs::read(&file).unwrap();
    let record = offset as usize - (1 + 8 + 2 + 4 + 8 + 8);
    bytes[record] = 0x7f;
    std::fs::write(&file, &bytes).unwrap();
    let e = Bag::open(&file)
        .unwrap()
        .for_each(&["/image".into()], &[], |_| Ok(()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("b.mcap") && e.contains("damaged MCAP"), "{e}");
    // A location past the end of the file.
    let past = Location {
        file: 0,
        at: Position::Bytes {
            offset: bytes.len() as u64 - 4,
            len,
        },
    };
    let e = bag.read_direct(past).unwrap_err().to_string();
    assert!(e.contains("b.mcap") && e.contains("past the end"), "{e}");
}
