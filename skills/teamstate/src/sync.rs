//! Sync messages, their wire format, and what a robot remembers about each peer.
//!
//! Wire format: the 4 bytes `SPTS`, a format version byte, then the message in
//! [postcard](https://docs.rs/postcard) (serde, varint integers, no field names). A binary format
//! because scans and map blobs dominate the traffic and JSON would triple their size; postcard
//! because it is compact, schema-free for our own types and rejects trailing or truncated input.
//!
//! Two versions: 2 is the bare message (the simulator's, one process, no sessions, nothing
//! signed); 3 adds a trailer after it — the sender's session (which boot of the sender this
//! is) and, on a secured team, each record's signature by its writer and then the sender's
//! signature over every byte before it.

use std::collections::{BTreeSet, HashMap, VecDeque};

use serde::{Deserialize, Serialize};
use spomp_core::RobotId;

use crate::auth::{SIGNATURE_BYTES, Signature};
use crate::error::SyncError;
use crate::intern::KeyNo;
use crate::record::{Record, Tier};

const MAGIC: &[u8; 4] = b"SPTS";
/// The bare message.
const FORMAT_VERSION: u8 = 2;
/// The message and a trailer: session and signatures.
const FORMAT_VERSION_TRAILER: u8 = 3;
/// Bytes before the postcard payload.
pub(crate) const HEADER_BYTES: usize = MAGIC.len() + 1;

/// Which of the receiver's messages the sender has received: `upto` and, in bit `i` of `mask`,
/// message `upto − i` (a 64-message window, so reordering and loss are both visible).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ack {
    /// Highest message sequence number received from the addressee (0 = none yet).
    pub upto: u32,
    /// Bit i set: message `upto − i` was received.
    pub mask: u64,
}

impl Ack {
    /// Whether message `seq` is acknowledged.
    pub fn covers(&self, seq: u32) -> bool {
        seq != 0 && seq <= self.upto && (self.upto - seq) < 64 && self.mask >> (self.upto - seq) & 1 == 1
    }

    /// Whether message `seq` was received already, or is older than the 64-message window
    /// (so whether it was cannot be told).
    pub fn seen_or_older(&self, seq: u32) -> bool {
        seq <= self.upto && (self.upto - seq >= 64 || self.covers(seq))
    }

    /// Records the receipt of message `seq`.
    pub(crate) fn record(&mut self, seq: u32) {
        if seq == 0 {
            return;
        }
        if seq > self.upto {
            let shift = seq - self.upto;
            self.mask = if shift >= 64 { 0 } else { self.mask << shift };
            self.mask |= 1;
            self.upto = seq;
        } else if self.upto - seq < 64 {
            self.mask |= 1 << (self.upto - seq);
        }
    }
}

/// One pairwise sync message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyncMessage {
    /// Sender.
    pub from: RobotId,
    /// Addressee.
    pub to: RobotId,
    /// Sender's sequence number for messages to this addressee (from 1).
    pub seq: u32,
    /// Which of the addressee's messages the sender has received.
    pub ack: Ack,
    /// The sender knows (from acknowledgements) that the addressee holds everything the sender
    /// holds. Together with the same statement the other way, this is "sync complete".
    pub peer_has_all: bool,
    /// The sender needs this message acknowledged: it carries records, or a `peer_has_all` the
    /// addressee has not acknowledged yet. Acknowledgement-only messages do not ask, so two
    /// robots never acknowledge each other's acknowledgements forever.
    pub wants_ack: bool,
    /// Records the addressee is not known to hold, highest priority first.
    pub records: Vec<Record>,
    /// Which boot of the sender this is (0: a sender that never restarts, e.g. in the
    /// simulator). A peer that sees a newer session forgets what it knew of the sender's
    /// messages; an older one is a replay and is refused.
    #[serde(skip)]
    pub session: u64,
    /// The sender's signature over the whole message (a secured team), or None. The records'
    /// own signatures travel in [`Record::sig`].
    #[serde(skip)]
    pub signature: Option<Signature>,
}

/// The trailer of a version-3 message, before the sender's signature.
#[derive(Serialize, Deserialize)]
struct Trailer {
    session: u64,
    /// Each record's signature by its writer, in record order (None: a mission record, which no
    /// robot writes); None when the message is not signed.
    record_sigs: Option<Vec<Option<Signature>>>,
}

impl SyncMessage {
    /// Encodes the message (see the module doc for the format).
    pub fn encode(&self) -> Vec<u8> {
        let mut out = self.signed_part(self.signature.is_some());
        if let Some(sig) = &self.signature {
            out.extend_from_slice(&sig.0);
        }
        out
    }

    /// Every byte the sender's signature covers: all of the encoding of a message that is
    /// (`signed`) or is not signed, but the signature itself.
    pub(crate) fn signed_part(&self, signed: bool) -> Vec<u8> {
        let trailer = self.session != 0 || signed;
        let mut out = Vec::with_capacity(HEADER_BYTES + 64);
        out.extend_from_slice(MAGIC);
        out.push(if trailer { FORMAT_VERSION_TRAILER } else { FORMAT_VERSION });
        // Serialising plain data into a Vec cannot fail; fall back to the bare header if it ever
        // did, which any decoder rejects as malformed.
        let header = out.clone();
        let Ok(mut out) = postcard::to_extend(self, out) else { return header };
        if trailer {
            let record_sigs = signed.then(|| self.records.iter().map(|r| r.sig.as_deref().copied()).collect());
            match postcard::to_extend(&Trailer { session: self.session, record_sigs }, out) {
                Ok(o) => out = o,
                Err(_) => return header,
            }
        }
        out
    }

    /// Decodes a message, rejecting anything longer than `max_bytes`.
    pub fn decode_with_limit(bytes: &[u8], max_bytes: usize) -> Result<SyncMessage, SyncError> {
        if bytes.len() > max_bytes {
            return Err(SyncError::Oversized { size: bytes.len(), limit: max_bytes });
        }
        Self::decode(bytes)
    }

    /// Decodes a message.
    pub fn decode(bytes: &[u8]) -> Result<SyncMessage, SyncError> {
        let (version, payload) = match bytes.split_at_checked(HEADER_BYTES) {
            Some((head, payload))
                if &head[..4] == MAGIC && (head[4] == FORMAT_VERSION || head[4] == FORMAT_VERSION_TRAILER) =>
            {
                (head[4], payload)
            }
            _ => return Err(SyncError::BadHeader),
        };
        let malformed = |e: postcard::Error| SyncError::Malformed(e.to_string());
        let (mut msg, rest) = postcard::take_from_bytes::<SyncMessage>(payload).map_err(malformed)?;
        let rest = if version == FORMAT_VERSION_TRAILER {
            let (trailer, rest) = postcard::take_from_bytes::<Trailer>(rest).map_err(malformed)?;
            msg.session = trailer.session;
            match trailer.record_sigs {
                None => rest,
                Some(sigs) => {
                    if sigs.len() != msg.records.len() {
                        return Err(SyncError::Malformed(format!(
                            "{} record signatures for {} records",
                            sigs.len(),
                            msg.records.len()
                        )));
                    }
                    for (rec, sig) in msg.records.iter_mut().zip(sigs) {
                        rec.sig = sig.map(Box::new);
                    }
                    let (sig, rest) = rest
                        .split_first_chunk::<SIGNATURE_BYTES>()
                        .ok_or_else(|| SyncError::Malformed("the sender's signature is cut short".into()))?;
                    msg.signature = Some(Signature(*sig));
                    rest
                }
            }
        } else {
            rest
        };
        if !rest.is_empty() {
            return Err(SyncError::Malformed(format!("{} trailing bytes", rest.len())));
        }
        Ok(msg)
    }
}

impl SyncMessage {
    /// How many of `encoded_len` bytes (this message's encoding) each sync tier's records take,
    /// indexed by [`Tier`] (coordination, scans, maps); the header, acknowledgement and trailer
    /// count with coordination. For reporting what a link carried, e.g. how much a scan-sharing
    /// setting costs.
    pub fn bytes_by_tier(&self, encoded_len: usize) -> [u64; 3] {
        let mut by_tier = [0u64; 3];
        for r in &self.records {
            // A record that cannot be measured is counted with the header below.
            by_tier[r.tier() as usize] += postcard::experimental::serialized_size(r).unwrap_or(0) as u64;
        }
        let records: u64 = by_tier.iter().sum();
        by_tier[Tier::Coordination as usize] += (encoded_len as u64).saturating_sub(records);
        by_tier
    }
}

/// Encodes a message (free-function form of [`SyncMessage::encode`]).
pub fn encode(msg: &SyncMessage) -> Vec<u8> {
    msg.encode()
}

/// Decodes a message (free-function form of [`SyncMessage::decode`]).
pub fn decode(bytes: &[u8]) -> Result<SyncMessage, SyncError> {
    SyncMessage::decode(bytes)
}

/// A sent message whose fate is not known yet.
#[derive(Clone, Debug)]
pub(crate) struct InFlight {
    pub seq: u32,
    pub records: Vec<(KeyNo, u64)>,
}

/// The highest dot of each record a peer is known to hold, by the key's process-wide number
/// ([`KeyNo`]): for each peer, 8 bytes a mutable record and one bit an immutable one (its only
/// dot is 1). Every robot of a team holds every scan, so in a large team this table, one per
/// peer, would otherwise outweigh the records themselves.
#[derive(Clone, Debug, Default)]
pub(crate) struct DotsByKey {
    /// Dots of mutable records.
    dots: Vec<u64>,
    /// Bit n: the immutable record number n is held.
    held: Vec<u64>,
}

impl DotsByKey {
    /// The dot held for the key numbered `no`; 0 for none.
    pub fn get(&self, no: KeyNo) -> u64 {
        let n = no.index();
        if no.is_immutable() {
            self.held.get(n / 64).map_or(0, |word| word >> (n % 64) & 1)
        } else {
            self.dots.get(n).copied().unwrap_or(0)
        }
    }

    /// Raises the dot held for the key numbered `no` to at least `dot`.
    pub fn raise(&mut self, no: KeyNo, dot: u64) {
        if dot == 0 {
            return;
        }
        let n = no.index();
        if no.is_immutable() {
            // Validated records and own writes of immutable keys all have dot 1.
            debug_assert_eq!(dot, 1, "immutable record with dot {dot}");
            if self.held.len() <= n / 64 {
                self.held.resize(n / 64 + 1, 0);
            }
            self.held[n / 64] |= 1 << (n % 64);
        } else {
            if self.dots.len() <= n {
                self.dots.resize(n + 1, 0);
            }
            self.dots[n] = self.dots[n].max(dot);
        }
    }
}

/// What this robot knows about one peer.
#[derive(Clone, Debug, Default)]
pub(crate) struct PeerState {
    /// Sequence number of the last message made for the peer.
    pub last_sent_seq: u32,
    /// Sent messages with records, not yet acknowledged or presumed lost.
    pub in_flight: VecDeque<InFlight>,
    /// Record dots the peer is known to hold (acknowledged, or received from it).
    pub confirmed: DotsByKey,
    /// Record dots sent in messages still in flight, with the message's seq.
    pub sent: HashMap<KeyNo, (u64, u32)>,
    /// Records that may still have to go to the peer (changed since they were last considered,
    /// skipped for tier or budget, or in a lost message): the key numbers, as a peer on a
    /// link that carries only coordination collects every scan here.
    pub pending: BTreeSet<KeyNo>,
    /// Position in the local change log up to which changes were moved into `pending`.
    pub change_cursor: u64,
    /// Receipts of the peer's messages.
    pub received: Ack,
    /// The peer sent records (or news) we have not acknowledged yet.
    pub ack_owed: bool,
    /// `peer_has_all` of the peer's newest message.
    pub peer_says_we_have_all: bool,
    /// Seq of the peer's newest message.
    pub newest_from_peer: u32,
    /// `peer_has_all` we last told the peer.
    pub last_flag_sent: Option<bool>,
    /// Seq of the message that last carried `last_flag_sent` while it was unacknowledged.
    pub flag_seq: u32,
    /// The peer acknowledged a message carrying `last_flag_sent`. Until it does, the flag goes
    /// out again: a lost flag would otherwise leave "sync complete" false for good in a quiet
    /// team, where no later message reveals the loss.
    pub flag_confirmed: bool,
    /// The peer's session as of its newest message.
    pub session: u64,
}

impl PeerState {
    /// Highest dot of `key` the peer holds or will hold if in-flight messages arrive.
    pub fn known_dot(&self, no: KeyNo) -> u64 {
        let confirmed = self.confirmed.get(no);
        let sent = self.sent.get(&no).map_or(0, |s| s.0);
        confirmed.max(sent)
    }

    /// Processes the peer's acknowledgement of our messages.
    pub fn process_ack(&mut self, ack: Ack, max_in_flight: usize) {
        if self.flag_seq != 0 && ack.covers(self.flag_seq) {
            self.flag_confirmed = true;
        }
        let mut keep = VecDeque::with_capacity(self.in_flight.len());
        while let Some(msg) = self.in_flight.pop_front() {
            if msg.seq > ack.upto {
                keep.push_back(msg);
                continue;
            }
            let delivered = ack.covers(msg.seq);
            self.resolve(msg, delivered);
        }
        self.in_flight = keep;
        self.trim(max_in_flight);
    }

    /// Drops the oldest in-flight messages beyond the limit, presuming them lost.
    pub fn trim(&mut self, max_in_flight: usize) {
        while self.in_flight.len() > max_in_flight {
            if let Some(msg) = self.in_flight.pop_front() {
                self.resolve(msg, false);
            }
        }
        // A first exchange puts a whole state in flight at once; once it is resolved, give the
        // room back, or every pair that ever met keeps room for the whole state.
        if self.sent.capacity() > 64 && self.sent.len() * 4 < self.sent.capacity() {
            self.sent.shrink_to(self.sent.len() * 2);
        }
    }

    fn resolve(&mut self, msg: InFlight, delivered: bool) {
        for (no, dot) in msg.records {
            if delivered {
                self.confirmed.raise(no, dot);
            }
            if self.sent.get(&no).is_some_and(|s| s.1 == msg.seq) {
                self.sent.remove(&no);
                if !delivered {
                    self.pending.insert(no);
                }
            }
        }
    }
}
