//! JSON schemas (`jsonschema` encoding) of the recording's own JSON channels: decoded radio
//! frames and decoded LBC messages. `(name, schema)`.

/// One radio frame as one node's host wrote or received it (`/radio/<node>`).
pub const RADIO_FRAME: (&str, &str) = (
    "almc.RadioFrame",
    r#"{
  "title": "almc.RadioFrame",
  "description": "One radio-mac frame on a node's radio UART, decoded with radio_mac::wire",
  "type": "object",
  "properties": {
    "t_s": { "type": "number", "description": "world time of the frame's last byte, s" },
    "node": { "type": "string", "description": "ground, car<ID> or user" },
    "dir": { "type": "string", "enum": ["sent", "received"], "description": "written by the node's host, or delivered to it" },
    "bytes": { "type": "string", "description": "the frame on the wire (COBS, without the 0x00 delimiter), hex" },
    "kind": { "type": "string", "description": "state, heartbeat, request, reply, group, auth_command, ... or error" },
    "src": { "type": "string" },
    "dst": { "type": "string" },
    "error": { "type": "string", "description": "why the bytes are not a valid frame" }
  },
  "required": ["t_s", "node", "dir", "bytes", "kind"]
}"#,
);

/// One LBC-protocol message between a car and its LBC (`/car<ID>/lbc`).
pub const LBC_MESSAGE: (&str, &str) = (
    "almc.LbcMessage",
    r#"{
  "title": "almc.LbcMessage",
  "description": "One UBC<->LBC message, split by lbc_link::Deframer and decoded with lbc_link's types",
  "type": "object",
  "properties": {
    "t_s": { "type": "number", "description": "world time of the message's last byte, s" },
    "dir": { "type": "string", "enum": ["to_lbc", "from_lbc"] },
    "bytes": { "type": "string", "description": "the message on the wire, hex" },
    "symbol": { "type": "string", "description": "the command's symbol (MOVE_XY, ...), STREAM, CSER, UNKCMD, <symbol>_ERR" },
    "message": { "description": "the typed message (lbc_link's serde form)" },
    "sample": { "description": "a STREAM message decoded with the stream format the car set (UPD_SF)" },
    "error": { "type": "string", "description": "why the bytes are not a valid message" }
  },
  "required": ["t_s", "dir", "bytes"]
}"#,
);
