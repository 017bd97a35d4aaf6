// A Foxglove WebSocket client that is not mexone's: Foxglove's own @foxglove/ws-protocol client
// on node, decoding what it receives from the schemas the server advertises, as Foxglove does
// (JSON for JSON channels, protobufjs from the advertised FileDescriptorSet for protobuf ones).
// Prints one JSON object of what it saw; tests/foxglove_ws/test_foxglove.py asserts on it.
//   node client.js ws://127.0.0.1:PORT JOINT_STATES_TOPIC IMAGE_TOPIC
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const [url, jointTopic, imageTopic] = process.argv.slice(2);
// foxglove-sdk servers speak the protocol under the name "foxglove.sdk.v1" (the same messages
// as "foxglove.websocket.v1", the ws-protocol library's): offer both, as Foxglove does
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> {topic, schemaName, encoding, decode}
const subscriptions = new Map(); // subscription id -> channel id
const out = { channels: {}, joint_states: [], images: [], times: [], asset: null, urdf_seen: false };

function decoderFor(channel) {
  if (channel.encoding === "json") {
    return (data) => JSON.parse(new TextDecoder().decode(data));
  }
  if (channel.encoding === "protobuf") {
    const bytes = Buffer.from(channel.schema, "base64");
    const set = descriptor.FileDescriptorSet.decode(bytes);
    const root = protobuf.Root.fromDescriptor(set);
    const type = root.lookupType(channel.schemaName);
    return (data) => type.toObject(type.decode(data), { longs: Number, bytes: Buffer });
  }
  return null;
}

function finish() {
  console.log(JSON.stringify(out));
  client.close();
  process.exit(0);
}

client.on("advertise", (list) => {
  for (const channel of list) {
    channels.set(channel.id, { ...channel, decode: decoderFor(channel) });
    out.channels[channel.topic] = { schemaName: channel.schemaName, encoding: channel.encoding,
                                    schemaEncoding: channel.schemaEncoding };
    if (channel.topic === jointTopic || channel.topic === imageTopic) {
      subscriptions.set(client.subscribe(channel.id), channel.id);
    }
  }
});
client.on("time", (event) => out.times.push(Number(event.timestamp)));
client.on("message", (event) => {
  const channel = channels.get(subscriptions.get(event.subscriptionId));
  const msg = channel.decode(new Uint8Array(event.data.buffer, event.data.byteOffset,
                                            event.data.byteLength));
  if (channel.topic === jointTopic && out.joint_states.length < 5) {
    out.joint_states.push({ name: msg.name, position: msg.position, stamp: msg.header.stamp,
                            log_time: Number(event.timestamp) });
  } else if (channel.topic === imageTopic && out.images.length < 2) {
    const data = msg.data;
    let sum = 0;
    for (let i = 0; i < data.length; i++) sum += data[i];
    out.images.push({ width: msg.width, height: msg.height, encoding: msg.encoding, step: msg.step,
                      bytes: data.length, mean: sum / Math.max(1, data.length),
                      frame_id: msg.frameId });
  }
  if (out.joint_states.length >= 5 && out.images.length >= 2 && out.asset !== null) finish();
});
client.on("serverInfo", (info) => {
  out.server = { name: info.name, capabilities: info.capabilities };
  client.fetchAsset("package://mex_rb/urdf/mex_rb.urdf", 1);
  client.fetchAsset("package://mex_rb/../../../../etc/passwd", 2);
});
client.on("fetchAssetResponse", (response) => {
  if (response.requestId === 1) {
    out.asset = response.status === 0 ? new TextDecoder().decode(response.data).length : -1;
  } else {
    out.escape = response.status === 0 ? "served" : "refused";
  }
});
client.on("error", (error) => { out.error = String(error); finish(); });
setTimeout(finish, 60000);
