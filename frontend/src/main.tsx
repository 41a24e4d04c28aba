import { render } from "preact";
import { useEffect, useState } from "preact/hooks";
import { api, setToken, token, unwrap } from "./api/client";
import { AuditLog } from "./components/AuditLog";
import { CameraPanel } from "./components/CameraPanel";
import { Campaigns } from "./components/Campaigns";
import { LiveView } from "./components/LiveView";
import { MotionPanel } from "./components/MotionPanel";
import { NewCampaign } from "./components/NewCampaign";
import { PosePanel } from "./components/PosePanel";
import { Recorder } from "./components/Recorder";
import { ReferenceBar } from "./components/ReferenceBar";
import { ScenePanel } from "./components/ScenePanel";
import { StatusPanel } from "./components/StatusPanel";
import { Studies } from "./components/Studies";
import { TimeSeries } from "./components/TimeSeries";
import { ErrorContext, errorText } from "./errors";
import { connectLive, type LiveHandle, type LiveState } from "./live";
import { SampleBuffer } from "./plotWindow";
import "./style.css";

function App() {
  const [live, setLive] = useState<LiveState>(
    { connected: false, stale: true, pose: null, shown: null, samples: new SampleBuffer() });
  const [link, setLink] = useState<LiveHandle | null>(null);
  const [error, setError] = useState<string | null>(null);
  const [hasToken, setHasToken] = useState(!!token());
  const [preset, setPreset] = useState(0); // bumped: the new-campaign form shows a calibration
  useEffect(() => {
    const handle = connectLive(setLive);
    setLink(handle);
    return handle.close;
  }, []);

  // Escape anywhere on the page stops the turntable, like the STOP button.
  useEffect(() => {
    const onKey = (e: KeyboardEvent) => {
      if (e.key === "Escape") stop();
    };
    window.addEventListener("keydown", onKey);
    return () => window.removeEventListener("keydown", onKey);
  }, []);
  const askToken = () => {
    const t = window.prompt("API token (printed at the server's first start, stored in data/api_token):");
    setToken(t);
    setHasToken(!!t);
  };
  const stop = async () => {
    try {
      await unwrap(api.POST("/api/motion/stop"));
      setError(null);
    } catch (e) {
      setError(errorText(e));
    }
  };
  return (
    <ErrorContext.Provider value={setError}>
      <div class="page">
        {/* the header and the last error stay on screen wherever the page is scrolled: a
            panel far down (camera, campaigns) reports its refusals here */}
        <div class="top">
        <header>
          <h1>tofpose</h1>
          <span class={`badge ${live.connected ? "ok" : "warn"}`} data-testid="link">
            {live.connected ? "live" : "reconnecting…"}
          </span>
          <button class="token" onClick={askToken}>{hasToken ? "change token" : "enter API token"}</button>
          <button class="stop" data-testid="stop" onClick={stop} title="stop every axis (key: Esc)">STOP <span class="key">Esc</span></button>
        </header>
        {error && (
          <p class="error banner" role="alert">
            <span data-testid="error">{error}</span>
            <button class="dismiss" data-testid="error-dismiss" title="hide this message"
              onClick={() => setError(null)}>×</button>
          </p>
        )}
        </div>
        <main>
          {/* the images and the plots in one column, beside the pose: all on the first screen */}
          <div class="primary">
            <LiveView shown={live.shown} onDrawn={(i) => link?.ack(i)} />
            <TimeSeries samples={live.samples} />
          </div>
          <div class="side">
            <PosePanel pose={live.pose} stale={live.stale} latency={live.latency}>
              <ReferenceBar onCalibrate={() => setPreset((n) => n + 1)} />
            </PosePanel>
            <MotionPanel />
            <StatusPanel pose={live.pose} />
            <CameraPanel />
            <Recorder />
            <ScenePanel />
          </div>
          <Campaigns />
          <NewCampaign calibrationRequest={preset} />
          <Studies />
          <AuditLog />
        </main>
      </div>
    </ErrorContext.Provider>
  );
}

render(<App />, document.getElementById("app")!);
