//! The table of open connections: a total cap and a per-IP cap, with the
//! oldest *idle* connection (no request in flight) giving way to a new one.
//!
//! A flood of connections that send nothing therefore cannot lock real
//! clients out: each new connection at a cap closes the oldest idle one,
//! and a connection that sends its request at once is busy, not idle. Only
//! when every connection at the cap is busy is the new one refused (the
//! accept loop answers it 503 `too_many_connections` and closes it).

use std::collections::{BTreeMap, HashMap};
use std::net::IpAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use tokio::sync::Notify;

/// Why a connection was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Every connection is busy at `max_connections`.
    Total,
    /// Every connection from this address is busy at
    /// `max_connections_per_ip`.
    PerIp,
}

impl Refusal {
    /// The message answered to the refused client.
    pub fn message(self) -> &'static str {
        match self {
            Refusal::Total => "the server has its maximum of connections, all busy; retry later",
            Refusal::PerIp => {
                "this address has its maximum of connections, all busy; retry later or reuse one"
            }
        }
    }
}

/// One open connection, as the accept loop and the request layer see it.
#[derive(Debug)]
pub struct Connection {
    id: u64,
    table: ConnectionTable,
    /// Requests in flight on this connection.
    busy: Arc<AtomicUsize>,
    /// Notified when the table evicts this connection.
    evicted: Arc<Notify>,
}

impl Connection {
    /// A counter the request layer raises while a request is served.
    pub fn busy_counter(&self) -> Arc<AtomicUsize> {
        self.busy.clone()
    }

    /// Resolves when the table wants this connection closed.
    pub async fn evicted(&self) {
        self.evicted.notified().await
    }
}

impl Drop for Connection {
    fn drop(&mut self) {
        self.table.remove(self.id);
    }
}

#[derive(Debug)]
struct Entry {
    ip: IpAddr,
    busy: Arc<AtomicUsize>,
    evicted: Arc<Notify>,
}

#[derive(Debug, Default)]
struct Table {
    next_id: u64,
    /// By id, which is also the age order (oldest first).
    open: BTreeMap<u64, Entry>,
    per_ip: HashMap<IpAddr, usize>,
}

/// The open connections. Cheap to clone.
#[derive(Clone, Debug)]
pub struct ConnectionTable {
    inner: Arc<Mutex<Table>>,
    max_total: usize,
    max_per_ip: usize,
}

impl ConnectionTable {
    /// A table with these caps (both ≥ 1).
    pub fn new(max_total: usize, max_per_ip: usize) -> ConnectionTable {
        ConnectionTable {
            inner: Arc::new(Mutex::new(Table::default())),
            max_total: max_total.max(1),
            max_per_ip: max_per_ip.max(1),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Table> {
        // A panic while holding the lock leaves plain counters behind.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Admit a connection from `ip`, evicting the oldest idle one at a cap.
    pub fn admit(&self, ip: IpAddr) -> Result<Connection, Refusal> {
        let mut t = self.lock();
        if t.per_ip.get(&ip).copied().unwrap_or(0) >= self.max_per_ip
            && !evict_oldest_idle(&mut t, Some(ip))
        {
            return Err(Refusal::PerIp);
        }
        if t.open.len() >= self.max_total && !evict_oldest_idle(&mut t, None) {
            return Err(Refusal::Total);
        }
        let id = t.next_id;
        t.next_id += 1;
        let busy = Arc::new(AtomicUsize::new(0));
        let evicted = Arc::new(Notify::new());
        t.open.insert(
            id,
            Entry {
                ip,
                busy: busy.clone(),
                evicted: evicted.clone(),
            },
        );
        *t.per_ip.entry(ip).or_insert(0) += 1;
        Ok(Connection {
            id,
            table: self.clone(),
            busy,
            evicted,
        })
    }

    /// Open connections.
    pub fn open(&self) -> usize {
        self.lock().open.len()
    }

    /// Requests in flight over all connections.
    pub fn busy(&self) -> usize {
        self.lock()
            .open
            .values()
            .map(|e| e.busy.load(Ordering::SeqCst))
            .sum()
    }

    /// Ask every idle connection to close (the start of a drain).
    pub fn close_idle(&self) {
        for e in self.lock().open.values() {
            if e.busy.load(Ordering::SeqCst) == 0 {
                e.evicted.notify_one();
            }
        }
    }

    /// Ask every connection to close (the end of a drain).
    pub fn close_all(&self) {
        for e in self.lock().open.values() {
            e.evicted.notify_one();
        }
    }

    fn remove(&self, id: u64) {
        let mut t = self.lock();
        if let Some(e) = t.open.remove(&id) {
            forget_ip(&mut t, e.ip);
        }
    }
}

/// Evict the oldest idle connection (from `ip` only, when given): it leaves
/// the table now and is told to close. False when none is idle.
fn evict_oldest_idle(t: &mut Table, ip: Option<IpAddr>) -> bool {
    let victim = t
        .open
        .iter()
        .find(|(_, e)| ip.is_none_or(|ip| e.ip == ip) && e.busy.load(Ordering::SeqCst) == 0)
        .map(|(id, _)| *id);
    let Some(id) = victim else {
        return false;
    };
    if let Some(e) = t.open.remove(&id) {
        e.evicted.notify_one();
        forget_ip(t, e.ip);
    }
    true
}

fn forget_ip(t: &mut Table, ip: IpAddr) {
    if let Some(n) = t.per_ip.get_mut(&ip) {
        *n -= 1;
        if *n == 0 {
            t.per_ip.remove(&ip);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(last: u8) -> IpAddr {
        IpAddr::from([10, 0, 0, last])
    }

    #[test]
    fn idle_connections_give_way_and_busy_ones_refuse() {
        let table = ConnectionTable::new(3, 2);
        let a = table.admit(ip(1)).unwrap();
        let b = table.admit(ip(1)).unwrap();
        // Per-IP cap: the oldest idle one from that address gives way.
        let c = table.admit(ip(1)).unwrap();
        assert_eq!(table.open(), 2);
        assert!(!table.lock().open.contains_key(&a.id));
        // Busy connections are never evicted.
        b.busy.store(1, Ordering::SeqCst);
        c.busy.store(1, Ordering::SeqCst);
        assert_eq!(table.admit(ip(1)).unwrap_err(), Refusal::PerIp);
        let d = table.admit(ip(2)).unwrap();
        d.busy.store(1, Ordering::SeqCst);
        assert_eq!(table.admit(ip(3)).unwrap_err(), Refusal::Total);
        assert_eq!(table.busy(), 3);
        // Dropping a connection frees its place.
        drop(d);
        assert_eq!(table.open(), 2);
        let _e = table.admit(ip(3)).unwrap();
        assert_eq!(table.open(), 3);
        drop(a);
        assert_eq!(table.open(), 3, "an evicted connection is already gone");
    }
}
