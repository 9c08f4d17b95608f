//! Errors of the team database.

use spomp_core::GoalId;

/// What a local mutation or a query can fail with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TeamStateError {
    /// A parameter is out of range.
    #[error("invalid team-state parameter `{name}`: {reason}")]
    InvalidParams {
        /// Field name.
        name: &'static str,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The goal id is not in the database.
    #[error("unknown goal {0}")]
    UnknownGoal(GoalId),
    /// The goal (or a goal within the deconfliction radius) was visited already.
    #[error("goal {0} was already visited")]
    AlreadyVisited(GoalId),
    /// A robot with higher priority holds the goal.
    #[error("goal {goal} is held by higher-priority robot {robot}")]
    ClaimedByOther {
        /// Canonical id of the goal.
        goal: GoalId,
        /// The holder.
        robot: spomp_core::RobotId,
    },
    /// The operator cancelled the goal.
    #[error("goal {goal} was cancelled by operator command {by}")]
    Cancelled {
        /// Canonical id of the goal.
        goal: GoalId,
        /// The cancelling command.
        by: String,
    },
    /// A position, pose or scan has non-finite or out-of-range values.
    #[error("invalid input: {0}")]
    InvalidInput(String),
}

/// Why a sync message was rejected. A rejected message changes nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SyncError {
    /// More bytes than the configured maximum.
    #[error("message of {size} bytes exceeds the limit of {limit} bytes")]
    Oversized {
        /// Size of the message, bytes.
        size: usize,
        /// The limit, bytes.
        limit: usize,
    },
    /// Not a team-state message (wrong magic) or an unknown format version.
    #[error("not a team-state sync message (bad header)")]
    BadHeader,
    /// The payload does not decode.
    #[error("malformed sync message: {0}")]
    Malformed(String),
    /// The message is addressed to another robot or claims another sender.
    #[error("message from {claimed} to {to} delivered as from {actual} to {me}")]
    WrongAddress {
        /// Sender named in the message.
        claimed: String,
        /// Addressee named in the message.
        to: String,
        /// Sender the transport reported.
        actual: String,
        /// This robot.
        me: String,
    },
    /// The sender is not in the team's public keys (a secured team).
    #[error("sender {0} is not a member of the team")]
    NotAMember(String),
    /// A secured team got a message without signatures.
    #[error("unsigned message from {0} (the team requires signatures)")]
    Unsigned(String),
    /// A signature does not check: forged, altered, or signed with another key.
    #[error("bad signature on {what} from {from}")]
    BadSignature {
        /// The transport's sender.
        from: String,
        /// What was signed: the message, or which record.
        what: String,
    },
    /// A message from an earlier boot of its sender (a replay).
    #[error("message from {from}'s earlier session {session} (current: {current})")]
    StaleSession {
        /// The sender.
        from: String,
        /// The message's session.
        session: u64,
        /// The sender's newest session seen.
        current: u64,
    },
    /// A message of the sender's current session that was received already, or is older than
    /// the window of recent messages this robot remembers (a replay; a secured team only).
    #[error("message {seq} from {from} replayed (newest received: {newest})")]
    Replayed {
        /// The sender.
        from: String,
        /// The message's sequence number.
        seq: u32,
        /// The sender's newest sequence number received in this session.
        newest: u32,
    },
    /// A record in the message is inconsistent (e.g. key and body disagree, non-finite values).
    #[error("invalid record {index}: {reason}")]
    InvalidRecord {
        /// Position of the record in the message.
        index: usize,
        /// What is wrong.
        reason: String,
    },
}

impl SyncError {
    /// Every [`SyncError::kind`], for tables counted by kind (a fixed, small set).
    pub const KINDS: [&'static str; 10] = [
        "oversized",
        "bad_header",
        "malformed",
        "wrong_address",
        "not_a_member",
        "unsigned",
        "bad_signature",
        "stale_session",
        "replayed",
        "invalid_record",
    ];

    /// A short, fixed name of the kind of refusal (one of [`SyncError::KINDS`]): what a
    /// counter keyed by kind uses, so its size never depends on what a sender chose to send.
    pub fn kind(&self) -> &'static str {
        match self {
            SyncError::Oversized { .. } => "oversized",
            SyncError::BadHeader => "bad_header",
            SyncError::Malformed(_) => "malformed",
            SyncError::WrongAddress { .. } => "wrong_address",
            SyncError::NotAMember(_) => "not_a_member",
            SyncError::Unsigned(_) => "unsigned",
            SyncError::BadSignature { .. } => "bad_signature",
            SyncError::StaleSession { .. } => "stale_session",
            SyncError::Replayed { .. } => "replayed",
            SyncError::InvalidRecord { .. } => "invalid_record",
        }
    }
}
