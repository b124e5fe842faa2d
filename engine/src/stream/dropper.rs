//! Freeing evicted nodes off the frame thread. A prepared node holds up to megabytes in many
//! allocations (meshes, instances, ground pieces); freeing them, large blocks going back to the
//! OS, is work no frame needs to wait for, and a flight evicts hundreds of nodes a second. The
//! frame thread releases only the node's GPU objects itself (so the GPU allocators see their
//! frees in frame order, as before) and hands the rest to one thread at the workers' priority
//! that drops it.

use super::NodeWork;
use crossbeam_channel::Sender;
use std::thread::JoinHandle;

pub(super) struct Dropper {
    /// `None` only while the dropper itself is dropped (closing the channel stops the thread).
    to_thread: Option<Sender<Box<NodeWork>>>,
    thread: Option<JoinHandle<()>>,
}

impl Dropper {
    /// Starts the dropping thread; without it (the OS refused a thread) nodes are dropped in
    /// place, as before.
    pub(super) fn start() -> Self {
        let (tx, rx) = crossbeam_channel::unbounded::<Box<NodeWork>>();
        let thread = std::thread::Builder::new()
            .name("node-dropper".into())
            .spawn(move || {
                super::lower_priority();
                // Each node is dropped as it arrives; the loop ends when the sender is gone.
                for work in rx {
                    drop(work);
                }
            })
            .map_err(|e| log::warn!("evicted nodes are freed on the frame thread: {e}"))
            .ok();
        Self {
            to_thread: thread.as_ref().map(|_| tx),
            thread,
        }
    }

    /// Frees `work`: its GPU objects now, on the calling thread, the rest on the dropping
    /// thread.
    pub(super) fn drop_node(&self, mut work: Box<NodeWork>) {
        drop(std::mem::take(&mut work.gpu));
        match &self.to_thread {
            // A send fails only if the thread is gone (it panicked): the value comes back.
            Some(tx) => {
                if let Err(e) = tx.send(work) {
                    drop(e.into_inner());
                }
            }
            None => drop(work),
        }
    }
}

impl Drop for Dropper {
    /// Closes the channel and waits until every handed-over node is freed.
    fn drop(&mut self) {
        self.to_thread = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::{GpuSlots, Payload};
    use crate::terrain::quadtree::NodeKey;
    use std::sync::{Arc, Mutex};

    /// Records the name of the thread that drops it.
    #[derive(Debug)]
    struct Probe(Arc<Mutex<Vec<String>>>);

    impl Drop for Probe {
        fn drop(&mut self) {
            let name = std::thread::current().name().unwrap_or("").to_string();
            self.0.lock().expect("names").push(name);
        }
    }

    impl Payload for Probe {
        fn bytes(&self) -> usize {
            0
        }
    }

    /// A GPU object of a node, which the caller's thread frees.
    struct GpuProbe(#[allow(dead_code)] Probe);

    /// The GPU objects are freed on the caller's thread before `drop_node` returns; the payloads
    /// on the dropping thread; all of them by the time the dropper is gone.
    #[test]
    fn gpu_objects_go_at_once_and_the_rest_on_the_dropping_thread() {
        let names: Arc<Mutex<Vec<String>>> = Arc::new(Mutex::new(Vec::new()));
        let caller = std::thread::current().name().unwrap_or("").to_string();
        assert_ne!(caller, "node-dropper");
        let on = |who: &str| {
            let names = names.lock().expect("names");
            names.iter().filter(|n| n.as_str() == who).count()
        };
        let dropper = Dropper::start();
        for i in 0..3 {
            let mut w = Box::new(NodeWork::new(NodeKey::ROOT.children()[i]));
            w.put(Probe(Arc::clone(&names)));
            let mut gpu = GpuSlots::default();
            gpu.put(GpuProbe(Probe(Arc::clone(&names))));
            w.gpu = gpu;
            dropper.drop_node(w);
            assert_eq!(
                on(&caller),
                i + 1,
                "GPU objects freed by the caller, at once"
            );
        }
        drop(dropper);
        assert_eq!(on(&caller), 3);
        assert_eq!(
            on("node-dropper"),
            3,
            "payloads freed on the dropping thread"
        );
    }
}
