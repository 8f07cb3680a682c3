//! A ROS 2 node of the volcal node set: a DDS participant on the domain given by
//! `ROS_DOMAIN_ID`, discovery limited to this host when `ROS_LOCALHOST_ONLY=1` (or
//! `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`), the node's remaps applied to every topic, and one
//! `mio` poll on which all its subscriptions wake the node loop.

use super::args::NodeArgs;
use anyhow::{anyhow, bail, Context as _, Result};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::dds::rustdds::{DomainParticipantBuilder, RTPSEntity};
use ros2_client::qos::QosProfile;
use ros2_client::{Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, Subscription};
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};
use volcal_msgs::RosMessage;

/// A subscription that decodes each message on its own: one that does not decode is counted,
/// reported with the topic and the reason, and skipped, so the messages behind it still arrive
/// and the node keeps going. A node's loop drains it with [`Inbox::next`] (or [`Inbox::drain`]).
pub struct Inbox<M: RosMessage> {
    sub: Subscription<M>,
    topic: String,
    undecodable: u64,
}

/// Undecodable messages reported one by one; after that, every power of two.
const REPORT_EACH: u64 = 10;

impl<M: RosMessage> Inbox<M> {
    /// The next message waiting, if any; undecodable ones on the way are counted and skipped.
    #[allow(clippy::should_implement_trait)] // not an Iterator: `None` means "none yet"
    pub fn next(&mut self) -> Option<M> {
        loop {
            match self.sub.take() {
                Ok(Some((m, _))) => return Some(m),
                Ok(None) => return None,
                Err(e) => {
                    self.undecodable += 1;
                    let n = self.undecodable;
                    if n <= REPORT_EACH || n.is_power_of_two() {
                        log::warn!(
                            "topic {}: message does not decode as {} ({n} so far, skipped): {e:?}",
                            self.topic,
                            M::type_name()
                        );
                    }
                }
            }
        }
    }

    /// Hands every message waiting to `f`.
    pub fn drain(&mut self, mut f: impl FnMut(M) -> Result<()>) -> Result<()> {
        while let Some(m) = self.next() {
            f(m)?;
        }
        Ok(())
    }
}

impl<M: RosMessage> Drop for Inbox<M> {
    fn drop(&mut self) {
        if self.undecodable > 0 {
            log::warn!(
                "topic {}: {} message(s) did not decode as {} and were skipped",
                self.topic,
                self.undecodable,
                M::type_name()
            );
        }
    }
}

/// Wall-clock time, nanoseconds since the Unix epoch (the stamp of every message).
pub fn now_ns() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0)
}

/// Where a node's DDS traffic goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DdsConfig {
    /// `ROS_DOMAIN_ID` (0..=232).
    pub domain_id: u16,
    /// Only the loopback interface: discovery and data stay on this host.
    pub localhost_only: bool,
}

impl DdsConfig {
    /// From the ROS 2 environment variables.
    pub fn from_env() -> Result<DdsConfig> {
        let domain_id = match std::env::var("ROS_DOMAIN_ID") {
            Ok(s) if !s.trim().is_empty() => s
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| anyhow!("ROS_DOMAIN_ID={s:?}: expected an integer from 0 to 232"))?,
            _ => 0,
        };
        let localhost_only = std::env::var("ROS_LOCALHOST_ONLY").is_ok_and(|v| v.trim() == "1")
            || std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE").is_ok_and(|v| v.trim().eq_ignore_ascii_case("LOCALHOST"));
        Ok(DdsConfig { domain_id, localhost_only })
    }

    /// A `ros2-client` context with this configuration.
    pub fn context(&self) -> Result<Context> {
        let mut b = DomainParticipantBuilder::new(self.domain_id).same_host_loopback(true);
        if self.localhost_only {
            b = b.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
        }
        let dp =
            b.build().map_err(|e| anyhow!("cannot create the DDS participant on domain {}: {e:?}", self.domain_id))?;
        Context::from_domain_participant(dp).map_err(|e| anyhow!("cannot create the ROS 2 context: {e:?}"))
    }
}

/// A running node.
pub struct RosNode {
    /// Node name (as given by `-r __node:=`, or the default).
    pub name: String,
    pub args: NodeArgs,
    pub dds: DdsConfig,
    // Field order matters: the node must be dropped before its context.
    node: Node,
    _context: Context,
    poll: Poll,
    events: Events,
    next_token: usize,
}

impl RosNode {
    /// Creates the node from its arguments and the ROS 2 environment.
    pub fn new(args: NodeArgs, default_name: &str) -> Result<RosNode> {
        RosNode::with_config(args, default_name, DdsConfig::from_env()?)
    }

    /// Creates the node on an explicit domain (tests, benchmarks, the demo).
    pub fn with_config(args: NodeArgs, default_name: &str, dds: DdsConfig) -> Result<RosNode> {
        let name = args.name.clone().unwrap_or_else(|| default_name.to_string());
        let ns = args.namespace.clone().unwrap_or_else(|| "/".to_string());
        let context = dds.context()?;
        let node_name = NodeName::new(&ns, &name).map_err(|e| anyhow!("node name {ns}/{name}: {e}"))?;
        let node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| anyhow!("cannot create node {name}: {e:?}"))?;
        Ok(RosNode {
            name,
            args,
            dds,
            node,
            _context: context,
            poll: Poll::new().context("cannot create the event poll")?,
            events: Events::with_capacity(64),
            next_token: 0,
        })
    }

    /// The underlying `ros2-client` node.
    pub fn ros_node(&self) -> &Node {
        &self.node
    }

    /// The topic name after this node's remaps.
    pub fn resolve(&self, topic: &str) -> String {
        self.args.remap(topic)
    }

    fn topic<M: RosMessage>(&mut self, topic: &str, qos: &QosProfile) -> Result<ros2_client::dds::rustdds::Topic> {
        let resolved = self.resolve(topic);
        let name = Name::parse(&resolved).map_err(|e| anyhow!("topic {resolved}: {e}"))?;
        self.node
            .create_topic(&name, MessageTypeName::new(M::PACKAGE, M::NAME), qos)
            .map_err(|e| anyhow!("topic {resolved} ({}): {e:?}", M::type_name()))
    }

    /// A publisher of `M` on `topic` (remapped).
    pub fn publisher<M: RosMessage>(&mut self, topic: &str, qos: QosProfile) -> Result<Publisher<M>> {
        let t = self.topic::<M>(topic, &qos)?;
        self.node.create_publisher::<M>(&t, Some(qos)).map_err(|e| anyhow!("publisher on {topic}: {e:?}"))
    }

    /// A subscription to `M` on `topic` (remapped), waking [`Self::wait`].
    pub fn subscription<M: RosMessage>(&mut self, topic: &str, qos: QosProfile) -> Result<Inbox<M>> {
        let t = self.topic::<M>(topic, &qos)?;
        let mut s =
            self.node.create_subscription::<M>(&t, Some(qos)).map_err(|e| anyhow!("subscription to {topic}: {e:?}"))?;
        self.next_token += 1;
        self.poll
            .registry()
            .register(&mut s, Token(self.next_token), Interest::READABLE)
            .with_context(|| format!("cannot poll subscription {topic}"))?;
        Ok(Inbox { sub: s, topic: self.resolve(topic), undecodable: 0 })
    }

    /// Blocks until a subscription has data or `timeout` passes.
    pub fn wait(&mut self, timeout: Duration) {
        // Interrupted polls (a signal) simply return early.
        let _ = self.poll.poll(&mut self.events, Some(timeout));
    }

    /// Number of publishers discovered on a (remapped) topic.
    pub fn publisher_count(&self, topic: &str) -> usize {
        self.node.publisher_count(&self.resolve(topic))
    }

    /// Number of subscriptions of other participants discovered on a (remapped) topic: whether
    /// a reliable, volatile message written now reaches anyone (e.g. a cell's
    /// `joint_trajectory_controller` before the first trajectory).
    pub fn remote_subscription_count(&self, topic: &str) -> usize {
        let name = format!("rt/{}", self.resolve(topic).trim_start_matches('/'));
        let dp = self._context.domain_participant();
        let own = dp.guid().prefix;
        dp.discovered_readers()
            .iter()
            .filter(|r| r.subscription_topic_data.topic_name == name && r.reader_proxy.remote_reader_guid.prefix != own)
            .count()
    }

    /// Waits until every topic has a publisher; after `timeout`, names the missing ones.
    pub fn wait_for_publishers(&mut self, topics: &[&str], timeout: Duration) -> Result<()> {
        let start = Instant::now();
        loop {
            let missing: Vec<String> =
                topics.iter().filter(|t| self.publisher_count(t) == 0).map(|t| self.resolve(t)).collect();
            if missing.is_empty() {
                return Ok(());
            }
            if start.elapsed() >= timeout || super::shutdown::requested() {
                bail!(
                    "no publisher on topic{} {} after {:.1} s (is the node that publishes {} running, on ROS_DOMAIN_ID {}?)",
                    if missing.len() > 1 { "s" } else { "" },
                    missing.join(", "),
                    timeout.as_secs_f64(),
                    if missing.len() > 1 { "them" } else { "it" },
                    self.dds.domain_id
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits until every participant that publishes `of` (e.g. the recorder, found by its
    /// `/campaign/pairs` publisher) has a subscription on each of `topics` that this node's
    /// participant has discovered; after `timeout`, names the topics still missing.
    ///
    /// Why: reliable, volatile topics reach only the readers that the writer has matched when it
    /// writes. A node that starts acquiring as soon as the recorder's publisher is visible can
    /// otherwise send its first triggers and commands before the recorder's readers are known,
    /// and the recorder silently lacks them (seen under load: 178 of 960 points). RustDDS
    /// matches a local writer to a remote reader when that reader's SEDP announcement arrives,
    /// which is what the discovered-readers table records.
    pub fn wait_for_readers(&mut self, topics: &[&str], of: &str, timeout: Duration) -> Result<()> {
        let dp = self._context.domain_participant();
        let dds_name = |t: &str| format!("rt/{}", self.resolve(t).trim_start_matches('/'));
        let start = Instant::now();
        loop {
            let owners: std::collections::BTreeSet<_> = dp
                .discovered_writers()
                .iter()
                .filter(|w| w.publication_topic_data.topic_name == dds_name(of))
                .map(|w| w.writer_proxy.remote_writer_guid.prefix)
                .collect();
            let readers = dp.discovered_readers();
            let missing: Vec<String> = topics
                .iter()
                .filter(|t| {
                    let name = dds_name(t);
                    !owners.iter().all(|o| {
                        readers.iter().any(|r| {
                            r.subscription_topic_data.topic_name == name
                                && r.reader_proxy.remote_reader_guid.prefix == *o
                        })
                    })
                })
                .map(|t| self.resolve(t))
                .collect();
            if !owners.is_empty() && missing.is_empty() {
                return Ok(());
            }
            if start.elapsed() >= timeout || super::shutdown::requested() {
                bail!(
                    "the node publishing {} has no subscription to {} after {:.1} s, so it would not record them",
                    self.resolve(of),
                    if owners.is_empty() { "anything".to_string() } else { missing.join(", ") },
                    timeout.as_secs_f64()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Warns about parameters that were given but never read.
    pub fn warn_unused_parameters(&self) {
        for p in self.args.unused() {
            log::warn!("unknown parameter {p:?} (ignored)");
        }
    }
}

/// Sets up logging for a node binary: `level: message` on stderr (`volcal launch` adds the node
/// name), RustDDS internals silenced (they warn about every
/// locator it does not use on loopback) unless `RUST_LOG` says otherwise.
pub fn init_logging() {
    let _ = env_logger::Builder::from_env(
        env_logger::Env::default().default_filter_or("info,rustdds=off,ros2_client=error,mio=warn"),
    )
    .format(|buf, record| {
        use std::io::Write;
        writeln!(buf, "{}: {}", record.level().as_str().to_ascii_lowercase(), record.args())
    })
    .try_init();
}
