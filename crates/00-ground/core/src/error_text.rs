//! An error told in one line: its message and its sources, `: `-joined, the way a person reads
//! it. A source whose text the line already holds is left out: a wrapper that quotes its source
//! (`"the joint solve: {0}"` with that source attached) would otherwise say it twice.

/// `error` and its sources in one line, each said once.
pub fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        let said = e.to_string();
        if !text.contains(&said) {
            text.push_str(": ");
            text.push_str(&said);
        }
        source = e.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::error_chain;

    #[derive(Debug, thiserror::Error)]
    #[error("robot rotations are all about nearly one axis")]
    struct Inner;

    #[derive(Debug, thiserror::Error)]
    enum Outer {
        #[error("solving failed")]
        Wraps(#[source] Inner),
        #[error("the solve: {0}")]
        Quotes(#[source] Inner),
    }

    #[test]
    fn each_cause_is_said_once() {
        assert_eq!(
            error_chain(&Outer::Wraps(Inner)),
            "solving failed: robot rotations are all about nearly one axis"
        );
        assert_eq!(
            error_chain(&Outer::Quotes(Inner)),
            "the solve: robot rotations are all about nearly one axis"
        );
    }
}
