//! The loop's side of a writer thread (the bag, the ROS 2 node): messages
//! are handed over without waiting; when the thread falls behind they are
//! dropped and counted, never the loop held up.

use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use tracing::warn;

/// A bounded, non-blocking queue to one thread.
#[derive(Debug)]
pub struct Handoff<T> {
    tx: Option<SyncSender<T>>,
    dropped: u64,
    /// Who falls behind, for the warning.
    to: &'static str,
}

impl<T> Handoff<T> {
    /// A queue of `capacity` to `to` (named in the warning) and its end.
    pub fn new(capacity: usize, to: &'static str) -> (Handoff<T>, Receiver<T>) {
        let (tx, rx) = sync_channel(capacity);
        (
            Handoff {
                tx: Some(tx),
                dropped: 0,
                to,
            },
            rx,
        )
    }

    /// Hands `item` over, or drops it (counted) if the queue is full; once
    /// the thread has gone (it stopped on an error), nothing more is sent.
    pub fn send(&mut self, item: T) {
        let Some(tx) = &self.tx else { return };
        match tx.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.dropped += 1;
                if self.dropped == 1 {
                    warn!("{} falls behind: messages are dropped", self.to);
                }
            }
            Err(TrySendError::Disconnected(_)) => self.tx = None,
        }
    }

    /// Closes the queue (the thread finishes what it holds) and says how
    /// many were dropped.
    pub fn close(&mut self) {
        self.tx = None;
        if self.dropped > 0 {
            warn!(dropped = self.dropped, "messages did not reach {}", self.to);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_drops_and_counts_and_a_gone_thread_ends_sending() {
        let (mut h, rx) = Handoff::new(2, "the test");
        for k in 0..5 {
            h.send(k);
        }
        assert_eq!(h.dropped, 3);
        assert_eq!(rx.try_iter().collect::<Vec<_>>(), [0, 1]);
        drop(rx);
        h.send(9);
        assert!(h.tx.is_none());
    }
}
