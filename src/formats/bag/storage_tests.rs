//! The storage layer streams: [`Bag::for_each`] lends each message with its location, and
//! [`MessageAt`] reads single messages again by location, in any order, with the right bytes (an
//! MCAP file read forward, started again only for a request behind the last few kept).

use std::collections::BTreeMap;
use std::path::Path;

use super::storage::{Bag, BagFormat, Location};

/// Message `i`'s payload: its own length and bytes, so a mix-up shows.
fn payload(i: usize) -> Vec<u8> {
    vec![i as u8; 50 + i]
}

/// An MCAP file with `n` messages alternating between `/image` and `/tf`, zstd chunks of a few
/// messages each.
fn write_mcap(file: &Path, n: usize) {
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
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
    bag.for_each(&["/image".to_string()], |m| {
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
    write_mcap(&mcap, n);
    write_db3(&db3, n);
    for (file, format) in [(mcap, BagFormat::Mcap), (db3, BagFormat::Sqlite3)] {
        let bag = Bag::open(&file).unwrap();
        assert_eq!(bag.format(), format);
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
    write_mcap(&file, 10);
    let bag = Bag::open(&file).unwrap();
    let e = bag
        .message_at("/image")
        .data(Location { file: 0, at: 99 })
        .unwrap_err()
        .to_string();
    assert!(e.contains("b.mcap") && e.contains("message 99"), "{e}");
}
