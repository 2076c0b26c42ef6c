// A Foxglove WebSocket client (subprotocol foxglove.websocket.v1) for the viewer: it subscribes to
// every channel the server advertises, decodes each message by its schema (the .proto files the
// page's own server serves under /schemas, parsed by protobufjs), and sends the protocol's playback
// controls when the server replays a recording (capability rangedPlayback).
/* global protobuf */

const SUBPROTOCOL = "foxglove.websocket.v1";
const MESSAGE_DATA = 1, TIME = 2, PLAYBACK_STATE = 5;  // server binary opcodes
const PLAYBACK_CONTROL_REQUEST = 3;                   // client binary opcode
export const PlaybackStatus = { playing: 0, paused: 1, buffering: 2, ended: 3 };

/** Events: "info" (serverInfo), "message" ({topic, schemaName, time, value}), "time" (ns),
 * "playback" ({status, time, speed}), "status" (a server status), "close". */
export class Connection extends EventTarget {
  constructor(url) {
    super();
    this.url = url;
    this.info = null;
    this.channels = new Map();       // channel id → {topic, schemaName, type}
    this.subscriptions = new Map();  // subscription id → channel id
    this.root = null;
    this.nextSubscription = 1;
  }

  async connect() {
    // Every schema the viewer decodes, with their imports (protobuf's own come bundled).
    this.root = new protobuf.Root();
    this.root.resolvePath = (origin, target) => (target.startsWith("google/protobuf/") ? target : `/schemas/${target}`);
    await this.root.load(["foxglove/SceneUpdate.proto", "foxglove/FrameTransforms.proto", "foxglove/PointCloud.proto",
      "foxglove/RawImage.proto", "foxglove/CameraCalibration.proto", "m3dp/RunStats.proto"], { keepCase: true });
    this.ws = new WebSocket(this.url, [SUBPROTOCOL]);
    this.ws.binaryType = "arraybuffer";
    this.ws.onmessage = (event) => (typeof event.data === "string" ? this.onText(JSON.parse(event.data)) : this.onBinary(event.data));
    this.ws.onclose = () => this.emit("close", {});
    this.ws.onerror = () => this.emit("status", { level: 2, message: `cannot reach ${this.url}` });
  }

  emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }

  onText(message) {
    if (message.op === "serverInfo") {
      this.info = message;
      this.emit("info", message);
    } else if (message.op === "advertise") {
      const subscriptions = [];
      for (const channel of message.channels) {
        if (channel.encoding !== "protobuf") continue;
        let type = null;
        try {
          type = this.root.lookupType(channel.schemaName);
        } catch {
          continue;  // a schema the viewer does not draw
        }
        this.channels.set(channel.id, { topic: channel.topic, schemaName: channel.schemaName, type });
        const id = this.nextSubscription++;
        this.subscriptions.set(id, channel.id);
        subscriptions.push({ id, channelId: channel.id });
      }
      if (subscriptions.length) this.ws.send(JSON.stringify({ op: "subscribe", subscriptions }));
    } else if (message.op === "status") {
      this.emit("status", message);
    }
  }

  onBinary(buffer) {
    const view = new DataView(buffer);
    const opcode = view.getUint8(0);
    if (opcode === MESSAGE_DATA) {
      const channel = this.channels.get(this.subscriptions.get(view.getUint32(1, true)));
      if (!channel) return;
      const time = Number(view.getBigUint64(5, true));
      const value = channel.type.decode(new Uint8Array(buffer, 13));
      this.emit("message", { topic: channel.topic, schemaName: channel.schemaName, time, value });
    } else if (opcode === TIME) {
      this.emit("time", Number(view.getBigUint64(1, true)));
    } else if (opcode === PLAYBACK_STATE) {
      this.emit("playback", { status: view.getUint8(1), time: Number(view.getBigUint64(2, true)), speed: view.getFloat32(10, true) });
    }
  }

  /** Whether the server replays a recording (and takes playback controls). */
  get ranged() {
    return Boolean(this.info && this.info.capabilities.includes("rangedPlayback"));
  }

  /** Asks the replay to play or pause at `speed`, seeking to `seekTime` (ns) when given. */
  playback(playing, speed, seekTime) {
    const bytes = new ArrayBuffer(15);
    const view = new DataView(bytes);
    view.setUint8(0, PLAYBACK_CONTROL_REQUEST);
    view.setUint8(1, playing ? PlaybackStatus.playing : PlaybackStatus.paused);
    view.setFloat32(2, speed, true);
    view.setUint8(6, seekTime === undefined ? 0 : 1);
    view.setBigUint64(7, BigInt(Math.max(0, Math.round(seekTime ?? 0))), true);
    this.ws.send(bytes);
  }
}
