// A client of the open Foxglove WebSocket protocol, as a lab would write one: the published
// @foxglove/ws-protocol library with its default subprotocol (foxglove.websocket.v1) over
// Node's standard WebSocket. Subscribes to every advertised channel for SECONDS and prints
// one JSON line: the negotiated subprotocol, the server's name, the advertised channels and,
// per topic, the messages received and the byte length of the last one.
//
//   node --experimental-websocket scripts/foxglove-client.mjs ws://127.0.0.1:8765 6
//
// tests/backend/services/live/test_foxglove_relay.py runs it against `tofpose serve`.
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: named exports via the default

const { FoxgloveClient } = wsProtocol;

const [url, seconds = "5"] = process.argv.slice(2);
if (!url) {
  console.error("usage: foxglove-client.mjs WS_URL [SECONDS]");
  process.exit(2);
}

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const topicOf = new Map(); // subscription id -> topic
const report = {
  offered: FoxgloveClient.SUPPORTED_SUBPROTOCOL,
  subprotocol: null,
  serverName: null,
  channels: [],
  messages: {},
  lastBytes: {},
};

client.on("open", () => {
  report.subprotocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  report.serverName = info.name;
});
client.on("advertise", (channels) => {
  for (const ch of channels) {
    report.channels.push({ topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName });
    topicOf.set(client.subscribe(ch.id), ch.topic);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const topic = topicOf.get(subscriptionId);
  report.messages[topic] = (report.messages[topic] ?? 0) + 1;
  report.lastBytes[topic] = data.byteLength;
});
client.on("error", (err) => {
  console.error(`foxglove client error: ${err?.message ?? err}`);
  process.exit(1);
});
client.on("close", (event) => {
  if (report.subprotocol === null) {
    console.error(`closed before opening (code ${event?.code})`);
    process.exit(1);
  }
});

setTimeout(() => {
  console.log(JSON.stringify(report));
  client.close();
  process.exit(0);
}, Number(seconds) * 1000);
