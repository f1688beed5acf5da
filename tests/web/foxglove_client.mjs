// A Foxglove WebSocket client built on the protocol's reference client (npm
// @foxglove/ws-protocol, with ws), for the integration tests (tests/tests/it/foxglove.rs).
//
//   node foxglove_client.mjs URL SECONDS [--origin ORIGIN] [--protocol PROTOCOL]
//                            [--until advertised | --until TOPIC:N]
//
// Connects, subscribes to every channel advertised, and after SECONDS (or as soon as the
// channels are advertised, or TOPIC has N messages: a loaded host takes its time, which no
// fixed window allows for) prints one JSON object:
// the server's info, the channels as advertised, per topic the messages received, the first
// message of each topic (decoded from JSON) with its time stamp (ns, as a string), and the
// status messages. A connection the server refuses prints {"refused": "..."} with its answer.
import wsProtocol from "@foxglove/ws-protocol";
import { WebSocket } from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, seconds, ...rest] = process.argv.slice(2);
const option = (name) => {
  const k = rest.indexOf(name);
  return k >= 0 ? rest[k + 1] : undefined;
};
const origin = option("--origin");
const protocol = option("--protocol") ?? FoxgloveClient.SUPPORTED_SUBPROTOCOL;
const until = option("--until");
const [untilTopic, untilCount] =
  until && until !== "advertised"
    ? [until.slice(0, until.lastIndexOf(":")), Number(until.slice(until.lastIndexOf(":") + 1))]
    : [undefined, undefined];

const ws = new WebSocket(url, [protocol], origin ? { headers: { Origin: origin } } : {});
ws.on("unexpected-response", (_req, res) => {
  let body = "";
  res.on("data", (d) => (body += d));
  res.on("end", () => {
    console.log(JSON.stringify({ refused: `${res.statusCode}: ${body}` }));
    process.exit(0);
  });
});
const client = new FoxgloveClient({ ws });
const out = { serverInfo: null, protocol: null, channels: [], counts: {}, first: {}, statuses: [] };
const topicOf = new Map();
client.on("open", () => {
  out.protocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  out.serverInfo = info;
});
client.on("status", (s) => out.statuses.push(s));
client.on("advertise", (channels) => {
  for (const c of channels) {
    out.channels.push(c);
    const sub = client.subscribe(c.id);
    topicOf.set(sub, c.topic);
  }
  if (until === "advertised") {
    done();
  }
});
const decoder = new TextDecoder();
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = topicOf.get(subscriptionId);
  out.counts[topic] = (out.counts[topic] ?? 0) + 1;
  if (!(topic in out.first)) {
    out.first[topic] = { timestamp: timestamp.toString(), message: JSON.parse(decoder.decode(data)) };
  }
  if (topic === untilTopic && out.counts[topic] >= untilCount) {
    done();
  }
});
client.on("error", (e) => out.statuses.push({ error: String(e) }));
function done() {
  console.log(JSON.stringify(out));
  process.exit(0);
}
setTimeout(done, Number(seconds) * 1000);
