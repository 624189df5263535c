//! The DDS plumbing both node threads share: participant and node set-up,
//! the thread that owns them, QoS profiles, endpoint creation, and the
//! non-blocking queue helpers between a node thread and its users.

use std::net::Ipv4Addr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::time::Duration;

use ros2_client::dds::rustdds::{DomainParticipant, DomainParticipantBuilder, RTPSEntity};
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
    Subscription,
    qos::{History, WhenFull},
};
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::farewell::Farewell;
use super::{Ros2Config, Ros2StartOptions, Ros2Thread, TopicConfig, domain_id_from_env};
use crate::error::{IoError, Result};
use crate::msg::RosMessage;

pub(super) fn bump(a: &AtomicU64) {
    a.fetch_add(1, Ordering::Relaxed);
}

/// Queues `message` for the node thread without blocking; a full queue
/// (or a stopped node) drops it and counts `dropped`.
pub(super) fn try_queue<O>(tx: &SyncSender<O>, message: O, dropped: &AtomicU64) -> bool {
    match tx.try_send(message) {
        Ok(()) => true,
        Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
            bump(dropped);
            false
        }
    }
}

/// Node thread: waits up to 1 ms for an outgoing message, then publishes
/// every queued one.
pub(super) fn publish_queued<O>(out_rx: &Receiver<O>, mut publish: impl FnMut(O)) {
    match out_rx.recv_timeout(Duration::from_millis(1)) {
        Ok(message) => {
            publish(message);
            while let Ok(message) = out_rx.try_recv() {
                publish(message);
            }
        }
        Err(RecvTimeoutError::Timeout) => {}
        // Every publisher handle dropped: keep serving the inputs.
        Err(RecvTimeoutError::Disconnected) => std::thread::sleep(Duration::from_millis(1)),
    }
}

/// Counts one publish: `Some(ok)` from a publisher, `None` for a disabled
/// topic.
pub(super) fn count_publish(result: Option<bool>, published: &AtomicU64, errors: &AtomicU64) {
    match result {
        Some(true) => bump(published),
        Some(false) => bump(errors),
        None => {} // topic disabled
    }
}

/// Node thread: takes up to [`TAKE_BURST`] samples from `sub`. A payload
/// that does not decode counts `malformed`; a decoded one counts
/// `received` and goes through `accept` (which counts its own rejections
/// and returns `None` for them) into `tx`, where a full queue counts
/// `dropped`.
pub(super) fn take_burst<M: 'static + DeserializeOwned, T>(
    sub: &Subscription<M>,
    malformed: &AtomicU64,
    received: &AtomicU64,
    dropped: &AtomicU64,
    tx: &SyncSender<T>,
    mut accept: impl FnMut(M) -> Option<T>,
) {
    for _ in 0..TAKE_BURST {
        match sub.take() {
            Ok(None) => return,
            Err(_) => bump(malformed),
            Ok(Some((message, _))) => {
                bump(received);
                if let Some(item) = accept(message)
                    && tx.try_send(item).is_err()
                {
                    bump(dropped);
                }
            }
        }
    }
}

/// Resolves the domain id: the option, else `ROS_DOMAIN_ID`.
pub(super) fn domain_id(options: Ros2StartOptions) -> Result<u16> {
    match options.domain_id {
        Some(id) => Ok(id),
        None => domain_id_from_env(),
    }
}

/// Starts a node thread: `build` makes the DDS entities on the new thread
/// (errors come back from here, not later), then `run` serves until `stop`.
pub(super) fn spawn_node_thread<N: 'static>(
    thread_name: &str,
    stop: Arc<AtomicBool>,
    build: impl FnOnce() -> Result<N> + Send + 'static,
    run: fn(N) -> Result<()>,
) -> Result<Ros2Thread> {
    let (ready_tx, ready_rx) = sync_channel::<Result<()>>(1);
    // DDS entities are built on the thread that uses them.
    let join = std::thread::Builder::new()
        .name(thread_name.into())
        .spawn(move || match build() {
            Ok(node) => {
                let _ = ready_tx.send(Ok(()));
                run(node)
            }
            Err(e) => {
                let text = e.to_string();
                let _ = ready_tx.send(Err(e));
                Err(IoError::Ros {
                    context: "start".into(),
                    reason: text,
                })
            }
        })
        .map_err(|e| ros_err("node thread", e))?;
    let thread = Ros2Thread {
        stop,
        join: Some(join),
    };
    match ready_rx.recv() {
        Ok(Ok(())) => Ok(thread),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(ros_err("node thread", "ended before it was ready")),
    }
}

/// A node thread's ROS 2 node and DDS participant. Fields drop in order:
/// the node (its `ros_discovery_info` entry), then the participant. Keep it
/// the LAST field of a struct that also holds publishers and subscriptions,
/// so they are dropped (undeclared) while the participant still runs.
pub(super) struct DdsNode {
    pub(super) node: Node,
    context: Context,
    farewell: Farewell,
}

impl DdsNode {
    /// Drops `endpoints` (RustDDS undeclares them while its event loop
    /// runs), then the node and the participant (which stops its threads),
    /// then sends the [`Farewell`] that makes peers forget the participant
    /// and its endpoints at once. An error only if no farewell datagram
    /// could be sent at all.
    pub(super) fn shut_down<E>(self, endpoints: E) -> Result<()> {
        drop(endpoints);
        let Self {
            node,
            context,
            farewell,
        } = self;
        drop(node);
        drop(context);
        farewell
            .send()
            .map(|_| ())
            .map_err(|e| ros_err("farewell (SPDP dispose of the participant)", e))
    }
}

/// A DDS participant on `domain` (127.0.0.1 only with `loopback_only`) and
/// a node named `node_name` in the config's namespace.
pub(super) fn dds_node(config: &Ros2Config, domain: u16, node_name: &str) -> Result<DdsNode> {
    let mut builder = DomainParticipantBuilder::new(domain);
    if config.loopback_only {
        builder = builder
            .with_only_networks([Ipv4Addr::LOCALHOST])
            .same_host_loopback(true);
    }
    let participant = builder
        .build()
        .map_err(|e| ros_err(&format!("DDS participant on domain {domain}"), e))?;
    let farewell = Farewell {
        guid_prefix: participant_guid_prefix(&participant),
        domain,
        participant_id: participant.participant_id(),
        loopback_only: config.loopback_only,
    };
    let context =
        Context::from_domain_participant(participant).map_err(|e| ros_err("context", e))?;
    let name = NodeName::new(&config.namespace, node_name)
        .map_err(|e| ros_err(&format!("node name `{node_name}`"), e))?;
    let node = context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| ros_err("node", e))?;
    Ok(DdsNode {
        node,
        context,
        farewell,
    })
}

fn participant_guid_prefix(participant: &DomainParticipant) -> [u8; 12] {
    let mut prefix = [0u8; 12];
    prefix.copy_from_slice(participant.guid().prefix.as_ref());
    prefix
}

pub(super) fn ros_err(context: &str, e: impl std::fmt::Display) -> IoError {
    IoError::Ros {
        context: context.to_string(),
        reason: e.to_string(),
    }
}

/// `(namespace, base)` of an absolute topic name.
pub(super) fn split_name(topic: &str) -> Result<Name> {
    let (ns, base) = topic.rsplit_once('/').unwrap_or(("", topic));
    let ns = if ns.is_empty() { "/" } else { ns };
    Name::new(ns, base).map_err(|e| ros_err(&format!("topic `{topic}`"), e))
}

pub(super) fn type_name<M: RosMessage>() -> MessageTypeName {
    let mut parts = M::TYPE_NAME.split('/');
    let pkg = parts.next().unwrap_or_default();
    let name = parts.nth(1).unwrap_or_default();
    MessageTypeName::new(pkg, name)
}

/// Best effort, volatile, keep last 1: streams where a late sample is worth
/// nothing (inputs; PX4 outputs). As a subscription it matches reliable and
/// best-effort publishers.
pub(super) fn stream_qos() -> QosProfile {
    QosProfile::subscription_default()
}

/// Depth of [`reliable_qos`], ROS 2's default (`rmw_qos_profile_default`).
pub(super) const RELIABLE_DEPTH: usize = 10;

/// ROS 2's default profile (reliable, volatile, keep last 10), as offered by
/// a publisher that never waits for acknowledgements (`WhenFull::Fail`).
pub(super) fn reliable_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability_reliable(WhenFull::Fail)
        .history(History::KeepLast {
            depth: RELIABLE_DEPTH,
        })
}

pub(super) fn publisher<M: RosMessage + Serialize>(
    node: &mut Node,
    topic: &TopicConfig,
    qos: &QosProfile,
) -> Result<Option<Publisher<M>>> {
    if !topic.enabled {
        return Ok(None);
    }
    let context = format!("publisher `{}`", topic.name);
    let t = node
        .create_topic(&split_name(&topic.name)?, type_name::<M>(), qos)
        .map_err(|e| ros_err(&context, e))?;
    node.create_publisher::<M>(&t, Some(qos.clone()))
        .map(Some)
        .map_err(|e| ros_err(&context, e))
}

pub(super) fn subscription<M: RosMessage + DeserializeOwned>(
    node: &mut Node,
    topic: &TopicConfig,
) -> Result<Option<Subscription<M>>> {
    if !topic.enabled {
        return Ok(None);
    }
    let context = format!("subscription `{}`", topic.name);
    let t = node
        .create_topic(&split_name(&topic.name)?, type_name::<M>(), &stream_qos())
        .map_err(|e| ros_err(&context, e))?;
    node.create_subscription::<M>(&t, Some(stream_qos()))
        .map(Some)
        .map_err(|e| ros_err(&context, e))
}

/// At most this many samples are taken from one subscription per loop.
pub(super) const TAKE_BURST: usize = 256;
