import { describe, expect, it } from "vitest";
import { cameraSweep, cameraText, campaignRequest, INITIAL_FORM, metadataBody, type CampaignForm } from "./campaignForm";

const form = (part: Partial<CampaignForm>): CampaignForm => ({ ...INITIAL_FORM, ...part });

describe("the new-campaign form's camera settings and metadata", () => {
  it("sends the integration times as a sweep, and the metadata typed (trimmed)", () => {
    const r = campaignRequest(form({
      name: "exposure", integrationTimes: "100, 200 ,400", modulations: "6",
      metadata: { operator: " A. Operator ", target_name: "paper target #2", camera_serial: "", camera_firmware: "", notes: "lens cleaned" },
    }));
    expect(r).toEqual({
      body: {
        name: "exposure", frames_per_point: 20, record_raw: false,
        generator: { kind: "grid", yaw_deg: [0], pitch_deg: [0], roll_deg: [0], rail_mm: [12000] },
        camera_sweep: { integration_time_us: [100, 200, 400], modulation_frequency_mhz: [6] },
        operator: "A. Operator", target_name: "paper target #2", notes: "lens cleaned",
      },
    });
  });

  it("sends neither sweep nor metadata when nothing is typed (the camera as it is; serial and firmware from the device)", () => {
    const r = campaignRequest(form({ name: "plain", integrationTimes: "  " }));
    expect("body" in r && Object.keys(r.body).sort()).toEqual(["frames_per_point", "generator", "name", "record_raw"]);
    expect(cameraSweep(form({}))).toEqual({});
    expect(metadataBody(INITIAL_FORM.metadata)).toEqual({});
  });

  it("names the list and the item that is not a number, and sends nothing", () => {
    expect(campaignRequest(form({ integrationTimes: "100, fast" })))
      .toEqual({ error: 'integration times us (list): item "fast": "fast" is not a number' });
    expect(campaignRequest(form({ modulations: "6,," })))
      .toEqual({ error: 'modulation MHz (list): item "": empty: type a number' });
  });

  it("leaves the camera's limits to the server: an integration time beyond them is sent as typed", () => {
    const r = campaignRequest(form({ integrationTimes: "5000" }));
    expect("body" in r && r.body.camera_sweep).toEqual({ integration_time_us: [5000] });
  });

  it("describes a set-point's camera settings", () => {
    expect(cameraText({ integration_time_us: 200, modulation_frequency_mhz: 12 })).toBe("200 us, 12 MHz");
    expect(cameraText({ integration_time_us: 50 })).toBe("50 us");
    expect(cameraText(null)).toBe("-");
  });
});
