//! An in-process CAN bus: every endpoint receives the frames the other
//! endpoints send, as on a real bus (no arbitration, no error frames).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use async_trait::async_trait;
use tokio::sync::broadcast;

use super::{CanFrame, FrameStream};
use crate::DriverError;

/// A bus inside one process. Cheap to clone; endpoints come from
/// [`InProcessBus::endpoint`].
#[derive(Debug, Clone)]
pub struct InProcessBus {
    tx: broadcast::Sender<(u64, CanFrame)>,
    next_id: Arc<AtomicU64>,
}

impl InProcessBus {
    /// A bus whose endpoints each buffer up to `capacity` frames; a slower
    /// endpoint loses the oldest frames and counts them.
    pub fn new(capacity: usize) -> InProcessBus {
        let (tx, _) = broadcast::channel(capacity.max(1));
        InProcessBus {
            tx,
            next_id: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Attach a new node to the bus; it receives frames sent from now on.
    pub fn endpoint(&self, name: &str) -> BusEndpoint {
        BusEndpoint {
            name: name.to_string(),
            node: self.next_id.fetch_add(1, Ordering::Relaxed),
            tx: self.tx.clone(),
            rx: self.tx.subscribe(),
            lost: 0,
        }
    }
}

/// One node on an [`InProcessBus`].
#[derive(Debug)]
pub struct BusEndpoint {
    name: String,
    node: u64,
    tx: broadcast::Sender<(u64, CanFrame)>,
    rx: broadcast::Receiver<(u64, CanFrame)>,
    lost: u64,
}

impl BusEndpoint {
    /// Frames this endpoint lost because it read too slowly.
    pub fn lost(&self) -> u64 {
        self.lost
    }
}

#[async_trait]
impl FrameStream for BusEndpoint {
    fn id(&self) -> &str {
        &self.name
    }

    async fn send(&mut self, frame: &CanFrame) -> Result<(), DriverError> {
        // With no other node listening a real bus would see no ACK; the
        // in-process bus simply drops the frame, like a bus monitor.
        let _ = self.tx.send((self.node, frame.clone()));
        Ok(())
    }

    async fn recv(&mut self) -> Result<CanFrame, DriverError> {
        loop {
            match self.rx.recv().await {
                Ok((from, frame)) if from != self.node => return Ok(frame),
                Ok(_) => continue,
                Err(broadcast::error::RecvError::Lagged(n)) => self.lost += n,
                Err(broadcast::error::RecvError::Closed) => {
                    return Err(DriverError::Ended {
                        device: self.name.clone(),
                    })
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::CanId;

    #[tokio::test]
    async fn other_nodes_receive_and_the_sender_does_not() {
        let bus = InProcessBus::new(16);
        let mut a = bus.endpoint("a");
        let mut b = bus.endpoint("b");
        let f = CanFrame::new(CanId::Standard(0x181), &[1, 2, 3]).unwrap();
        a.send(&f).await.unwrap();
        assert_eq!(b.recv().await.unwrap(), f);
        let g = CanFrame::new(CanId::Extended(0x18FF_0001), &[9]).unwrap();
        b.send(&g).await.unwrap();
        assert_eq!(a.recv().await.unwrap(), g, "a skips nothing but its own");
    }

    #[tokio::test]
    async fn a_slow_reader_counts_what_it_lost() {
        let bus = InProcessBus::new(2);
        let mut a = bus.endpoint("a");
        let mut b = bus.endpoint("b");
        for k in 0..5u8 {
            a.send(&CanFrame::new(CanId::Standard(1), &[k]).unwrap())
                .await
                .unwrap();
        }
        let first = b.recv().await.unwrap();
        assert_eq!(first.data(), &[3]);
        assert_eq!(b.lost(), 3);
    }
}
