// The viser 3-D scene (served by the backend on a port of its own), embedded; pausing it
// goes through the API so that the scene's own checkbox and this one agree.
import { useEffect, useState } from "preact/hooks";
import { api } from "../api/client";
import type { components } from "../api/schema";

type Scene = components["schemas"]["ScenePublic"];

export function sceneUrl(port: number): string {
  return `${location.protocol}//${location.hostname}:${port}/`;
}

export function ScenePanel({ onError }: { onError: (m: string | null) => void }) {
  const [scene, setScene] = useState<Scene | null>(null);
  useEffect(() => {
    api<Scene>("GET", "/api/scene").then(setScene).catch((e) => onError(e.message));
  }, []);
  if (!scene) return null;
  const pause = async (paused: boolean) => {
    const before = scene;
    setScene({ ...scene, paused }); // the box follows the click; the server confirms
    try {
      setScene(await api<Scene>("PUT", "/api/scene", { paused }));
      onError(null);
    } catch (e) {
      setScene(before);
      onError((e as Error).message);
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
            <span class="small">green: matched, orange: in view but not matched, gray: out of view; blue wireframe: lab reference</span>
          </div>
          <iframe title="3-D scene (viser)" data-testid="scene-frame" src={sceneUrl(scene.port)} />
        </>
      ) : (
        <p class="small" data-testid="scene-off">{scene.reason}</p>
      )}
    </section>
  );
}
