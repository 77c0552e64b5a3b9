// Foxglove's published WebSocket client against a running live view.
//
//   node connect.mjs ws://127.0.0.1:PORT TOPIC [TOPIC ...]
//
// Connects with @foxglove/ws-protocol's FoxgloveClient over `ws`, offering the client's own
// subprotocol (FoxgloveClient.SUPPORTED_SUBPROTOCOL), waits until every TOPIC is advertised,
// subscribes to all of them and waits for one message on each. Prints one JSON line on stdout:
// {subprotocol, serverInfo, channels, messages: {topic: [count, first message as base64]}}.
// Exits 1 with the reason on stderr if that does not happen within 20 s.
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: no named exports under ESM
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, ...topics] = process.argv.slice(2);
if (!url || topics.length === 0) {
  console.error("usage: node connect.mjs ws://HOST:PORT TOPIC [TOPIC ...]");
  process.exit(2);
}

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const result = { subprotocol: null, serverInfo: null, channels: {}, messages: {} };
const subscriptions = new Map(); // subscription id -> topic

const timer = setTimeout(() => {
  const missing = topics.filter((t) => !(t in result.messages));
  console.error(`timed out; no message yet on ${missing.join(", ")}: ${JSON.stringify(result)}`);
  process.exit(1);
}, 20000);

function finishIfDone() {
  if (topics.every((t) => t in result.messages)) {
    clearTimeout(timer);
    console.log(JSON.stringify(result));
    client.close();
    process.exit(0);
  }
}

ws.on("unexpected-response", (_req, res) => {
  console.error(`handshake refused: HTTP ${res.statusCode} ${res.statusMessage}`);
  process.exit(1);
});
client.on("error", (err) => {
  console.error(`client error: ${err?.message ?? err}`);
  process.exit(1);
});
client.on("open", () => {
  result.subprotocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  result.serverInfo = { name: info.name, capabilities: info.capabilities };
});
client.on("advertise", (channels) => {
  for (const channel of channels) {
    result.channels[channel.topic] = {
      encoding: channel.encoding,
      schemaName: channel.schemaName,
      schemaEncoding: channel.schemaEncoding,
    };
    if (topics.includes(channel.topic)) {
      subscriptions.set(client.subscribe(channel.id), channel.topic);
    }
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const topic = subscriptions.get(subscriptionId);
  if (topic === undefined) return;
  const seen = result.messages[topic];
  const first = Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("base64");
  result.messages[topic] = seen ? [seen[0] + 1, seen[1]] : [1, first];
  finishIfDone();
});
client.on("close", (event) => {
  console.error(`closed before every topic had a message: code ${event?.code} ${event?.reason ?? ""}`);
  process.exit(1);
});
