// The viser 3-D scene (served by the backend on a port of its own), embedded; pausing it
// goes through the API so that the scene's own checkbox and this one agree.
import { api, unwrap } from "../api/client";
import { errorText, useReportError } from "../errors";
import { usePolling } from "../polling";

export function sceneUrl(port: number): string {
  return `${location.protocol}//${location.hostname}:${port}/`;
}

export function ScenePanel() {
  const report = useReportError();
  const polled = usePolling(() => unwrap(api.GET("/api/scene")), null);
  const scene = polled.data;
  if (!scene) return null;
  const pause = async (paused: boolean) => {
    const before = scene;
    polled.set({ ...scene, paused }); // the box follows the click; the server confirms
    try {
      polled.set(await unwrap(api.PUT("/api/scene", { body: { paused } })));
      report(null);
    } catch (e) {
      polled.set(before);
      report(errorText(e));
    }
  };
  return (
    <section class="card scene">
      <h2>3-D scene</h2>
      {scene.running && scene.port != null ? (
        <>
          <div class="form">
            <label>
              <input type="checkbox" data-testid="scene-pause" checked={scene.paused}
                onChange={(e) => pause((e.target as HTMLInputElement).checked)} /> pause scene
            </label>
            <a href={sceneUrl(scene.port)} target="_blank" rel="noopener" data-testid="scene-link">
              open in its own tab
            </a>
            <span class="small" data-testid="scene-legend">green: matched, orange: in view but not matched, gray: out of view; blue wireframe: lab reference; teal wireframe: truth (the pose the simulator rendered, simulator only); purple line: the target's trail ("Clear trail" in the scene's panel); grid and rulers in metres</span>
          </div>
          <iframe title="3-D scene (viser)" data-testid="scene-frame" src={sceneUrl(scene.port)} />
        </>
      ) : (
        <p class="small" data-testid="scene-off">{scene.reason}</p>
      )}
    </section>
  );
}
