// HTTP access to the hgrender API with the user's bearer token: JSON calls, raw float arrays and
// Server-Sent Events read over fetch (EventSource cannot send an Authorization header).

const TOKEN_KEY = "hgrender.token";

export function loadToken() {
  return window.localStorage.getItem(TOKEN_KEY) || "";
}

export function saveToken(token) {
  if (token) window.localStorage.setItem(TOKEN_KEY, token);
  else window.localStorage.removeItem(TOKEN_KEY);
}

/** An API error: HTTP status and the server's `detail` ("<field>: <what is wrong>"). */
export class ApiError extends Error {
  constructor(status, detail) {
    super(`HTTP ${status}: ${detail}`);
    this.status = status;
    this.detail = detail;
  }
}

/**
 * Client of the `/v1` API. `tokenProvider()` returns the current token (read at every call, so a new
 * token entered in the page takes effect at once).
 */
export class Api {
  constructor(baseUrl = "", tokenProvider = loadToken) {
    this.baseUrl = baseUrl.replace(/\/$/, "");
    this.tokenProvider = tokenProvider;
  }

  headers(extra = {}) {
    const token = this.tokenProvider();
    return token ? { Authorization: `Bearer ${token}`, ...extra } : { ...extra };
  }

  async request(path, options = {}) {
    const response = await fetch(this.baseUrl + path, { ...options, headers: this.headers(options.headers || {}) });
    if (!response.ok) {
      let detail = response.statusText;
      try {
        detail = (await response.json()).detail || detail;
      } catch {
        /* not JSON */
      }
      throw new ApiError(response.status, detail);
    }
    return response;
  }

  async json(path, options = {}) {
    const response = await this.request(path, options);
    return response.status === 204 ? null : response.json();
  }

  /** An object URL of an authenticated image (an <img src> cannot send the bearer token). */
  async blobUrl(path) {
    const response = await this.request(path);
    return URL.createObjectURL(await response.blob());
  }

  /** POST a JSON body. */
  async postJson(path, body) {
    return this.json(path, { method: "POST", body: JSON.stringify(body), headers: { "Content-Type": "application/json" } });
  }

  /**
   * A raw little-endian float array endpoint → {data: Float32Array, width, height, channels, headers}.
   * Float16 payloads are widened to Float32.
   */
  async floats(path) {
    const response = await this.request(path);
    const buffer = await response.arrayBuffer();
    const format = response.headers.get("X-Format") || (path.includes("format=f16") ? "f16" : "f32");
    const data = format === "f16" ? float16ToFloat32(new Uint16Array(buffer)) : new Float32Array(buffer);
    return {
      data,
      width: Number(response.headers.get("X-Width")),
      height: Number(response.headers.get("X-Height")),
      channels: Number(response.headers.get("X-Channels") || 1),
      headers: response.headers,
    };
  }

  /**
   * Follow a Server-Sent Events endpoint; calls onEvent(type, data) with parsed JSON data until the
   * stream ends or `signal` aborts. Resolves when the stream closes.
   */
  async events(path, onEvent, signal) {
    const response = await this.request(path, { signal, headers: { Accept: "text/event-stream" } });
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      buffer += value.replace(/\r\n/g, "\n");
      let end;
      while ((end = buffer.indexOf("\n\n")) >= 0) {
        const block = buffer.slice(0, end);
        buffer = buffer.slice(end + 2);
        let type = "message";
        const dataLines = [];
        for (const line of block.split("\n")) {
          if (line.startsWith("event:")) type = line.slice(6).trim();
          else if (line.startsWith("data:")) dataLines.push(line.slice(5).replace(/^ /, ""));
        }
        if (dataLines.length) onEvent(type, JSON.parse(dataLines.join("\n")));
      }
    }
  }
}

/** IEEE 754 half → single precision. */
export function float16ToFloat32(halves) {
  const out = new Float32Array(halves.length);
  for (let i = 0; i < halves.length; i++) {
    const h = halves[i];
    const sign = h & 0x8000 ? -1 : 1;
    const exponent = (h >> 10) & 0x1f;
    const fraction = h & 0x3ff;
    if (exponent === 0) out[i] = sign * Math.pow(2, -14) * (fraction / 1024);
    else if (exponent === 31) out[i] = fraction ? NaN : sign * Infinity;
    else out[i] = sign * Math.pow(2, exponent - 15) * (1 + fraction / 1024);
  }
  return out;
}
