//! Shared by the mock's integration tests: a mock controller on free loopback ports.

#![allow(unreachable_pub)] // test helpers, seen by the test files only

use std::net::Ipv4Addr;

use mocks::{MockUr, MockUrConfig, MockUrPorts};

/// Starts a mock UR with `config`, its RTDE, dashboard and script servers on free ports of
/// 127.0.0.1.
pub fn loopback_mock(config: MockUrConfig) -> MockUr {
    MockUr::start(MockUrConfig {
        address: Ipv4Addr::LOCALHOST.into(),
        ports: MockUrPorts {
            rtde: 0,
            dashboard: 0,
            script: 0,
        },
        ..config
    })
    .expect("mock starts")
}
