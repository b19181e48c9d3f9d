//! The job queue's state: which admitted jobs wait to run, in order, and how many may wait.
//!
//! Why it exists: admission, cancel, recovery and the dispatcher all change the queue; keeping
//! its state a plain struct (no locks, no I/O, no tokio) lets its rules be unit-tested on their
//! own. [`super::jobs::Service`] holds it behind one mutex and wakes the dispatcher after a
//! push. Capacity counts waiting jobs only: a running job has left the queue.

use std::collections::VecDeque;

/// The queue is full; nothing was added.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Full {
    /// Jobs waiting.
    pub queued: usize,
    /// The most that may wait.
    pub capacity: usize,
}

/// Waiting jobs, first in first out, bounded by `capacity` for new admissions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueueState {
    waiting: VecDeque<String>,
    capacity: usize,
}

impl QueueState {
    /// An empty queue admitting up to `capacity` waiting jobs.
    pub fn new(capacity: usize) -> Self {
        QueueState {
            waiting: VecDeque::new(),
            capacity,
        }
    }

    /// Jobs waiting.
    pub fn len(&self) -> usize {
        self.waiting.len()
    }

    /// Whether no job waits.
    pub fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Whether a new job would be refused now.
    pub fn check_admit(&self) -> Result<(), Full> {
        if self.waiting.len() >= self.capacity {
            return Err(Full {
                queued: self.waiting.len(),
                capacity: self.capacity,
            });
        }
        Ok(())
    }

    /// Append a newly admitted job (the caller checked [`QueueState::check_admit`] under the
    /// same lock as its store insert).
    pub fn push(&mut self, id: String) {
        self.waiting.push_back(id);
    }

    /// Append a job found unfinished at start-up: recovery never refuses, whatever the
    /// capacity, because every such job was accepted once.
    pub fn requeue(&mut self, id: String) {
        self.waiting.push_back(id);
    }

    /// The next job to run.
    pub fn pop(&mut self) -> Option<String> {
        self.waiting.pop_front()
    }

    /// Take a waiting job out (cancel); false when it is not waiting (running, finished or
    /// unknown).
    pub fn remove(&mut self, id: &str) -> bool {
        let before = self.waiting.len();
        self.waiting.retain(|j| j != id);
        self.waiting.len() != before
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_in_first_out() {
        let mut q = QueueState::new(8);
        for id in ["a", "b", "c"] {
            q.push(id.into());
        }
        assert_eq!(q.len(), 3);
        assert_eq!(q.pop().as_deref(), Some("a"));
        assert_eq!(q.pop().as_deref(), Some("b"));
        assert_eq!(q.pop().as_deref(), Some("c"));
        assert_eq!(q.pop(), None);
        assert!(q.is_empty());
    }

    #[test]
    fn a_full_queue_refuses_until_a_job_leaves() {
        let mut q = QueueState::new(2);
        assert_eq!(q.check_admit(), Ok(()));
        q.push("a".into());
        q.push("b".into());
        assert_eq!(
            q.check_admit(),
            Err(Full {
                queued: 2,
                capacity: 2
            })
        );
        q.pop();
        assert_eq!(q.check_admit(), Ok(()));
    }

    #[test]
    fn zero_capacity_refuses_every_admission() {
        let q = QueueState::new(0);
        assert_eq!(
            q.check_admit(),
            Err(Full {
                queued: 0,
                capacity: 0
            })
        );
    }

    #[test]
    fn recovery_requeues_past_the_capacity() {
        let mut q = QueueState::new(1);
        q.requeue("a".into());
        q.requeue("b".into());
        assert_eq!(q.len(), 2);
        assert!(q.check_admit().is_err());
    }

    #[test]
    fn cancel_removes_only_a_waiting_job_and_keeps_the_order() {
        let mut q = QueueState::new(8);
        for id in ["a", "b", "c"] {
            q.push(id.into());
        }
        assert!(q.remove("b"));
        assert!(!q.remove("b"));
        assert!(!q.remove("unknown"));
        assert_eq!(q.pop().as_deref(), Some("a"));
        assert_eq!(q.pop().as_deref(), Some("c"));
    }
}
